# amaranth: UnusedElaboratable=no
"""The machine's ports are declared once (hdl/signatures.py) and every component carrying them uses
that declaration; on-chip sources share one interface; components take keyword arguments.

The components built here are only inspected, never elaborated (hence the linter option above).
"""

from __future__ import annotations

import pytest
from amaranth.hdl import Fragment
from amaranth.lib import wiring

from bayesmachine.hdl.frontend.filters import FeatureFilter
from bayesmachine.hdl.frontend.linebuffer import LineBuffer
from bayesmachine.hdl.frontend.stereo import FrontEnd, StereoMachine, stereo_machine_params
from bayesmachine.hdl.frontend.words import WordGenerator
from bayesmachine.hdl.machine import BayesianMachine
from bayesmachine.hdl.machine.encoder import MAPEncoder
from bayesmachine.hdl.machine.operator import OperatorMatrix
from bayesmachine.hdl.machines import ParallelMachines
from bayesmachine.hdl.signatures import (
    MachineSignature,
    StereoSignature,
    entropy_layout,
    load_stream,
    result_stream,
)
from bayesmachine.hdl.smtj import SMTJEmulatedMachine, SMTJEmulator
from bayesmachine.hdl.sources import LFSRBank, OnChipSource, SobolGenerators, random_source
from bayesmachine.models import ModelParams
from bayesmachine.params import MachineParams, ParameterError
from bayesmachine.sources import SOURCE_KINDS
from bayesmachine.sources.lfsr import lfsr_specs

DMAX = 4


def _params(rng: str = "lfsr", **kwargs: object) -> MachineParams:
    return stereo_machine_params(DMAX, model=ModelParams(name="paper", dmax=DMAX), rng=rng, counter_max=4,
                                 **kwargs)


def _members(component: wiring.Component) -> set[str]:
    return set(component.signature.members)


@pytest.mark.parametrize("rng", sorted(SOURCE_KINDS))
def test_every_machine_top_has_the_declared_ports(rng: str) -> None:
    """The off-chip kinds ("external", "smtj") get entropy ports on the machine and on the stereo top
    alike: one declaration decides it (the stereo top used to expose them for "external" only)."""
    p = _params(rng)
    off_chip = not SOURCE_KINDS[rng].on_chip
    entropy = {"entropy", "entropy_ready"} if off_chip else set()
    machine = BayesianMachine(params=p)
    assert machine.signature == MachineSignature(p)
    assert _members(machine) == {"load", "result"} | entropy
    stereo = StereoMachine(params=p, model=ModelParams(name="paper", dmax=DMAX), width=20)
    assert stereo.signature == StereoSignature(p)
    assert _members(stereo) == {"pixels", "result"} | entropy
    assert stereo.signature.members["result"] == machine.signature.members["result"]
    if off_chip:
        for top in (machine, stereo):
            assert top.signature.members["entropy"].shape == entropy_layout(p)
            assert top.signature.members["entropy"].flow == wiring.In
            assert top.signature.members["entropy_ready"].flow == wiring.Out
    else:
        lanes = ParallelMachines(params=p, machines=2)
        assert lanes.signature == MachineSignature(p)


def test_the_passes_ports_are_declared_once() -> None:
    """census-lr: the StereoMachine's ``right_result`` is the right machine's result stream (with ready);
    the front end's ports are its word generators' own members (``maps`` and ``right_maps`` the lane
    builders', ``right_beats`` the right generator's ``beats``), not declared again."""
    from bayesmachine.hdl.frontend.words import pass_params
    from bayesmachine.hdl.signatures import map_stream

    model = ModelParams(name="census-lr", dmax=DMAX)
    p = stereo_machine_params(DMAX, model=model, counter_max=4)
    rp = pass_params(model, p, "right")
    stereo = StereoMachine(params=p, model=model, width=20)
    assert stereo.signature == StereoSignature(p, {"right": rp}) != StereoSignature(p)
    assert stereo.signature.members["right_result"] == wiring.Out(result_stream(rp))
    front = FrontEnd(params=p, model=model, width=20)
    own, right = (WordGenerator(params=pp, model=model, pass_name=name, output_columns=n)
                  for name, pp, n in ((None, p, 10), ("right", rp, 14)))
    members = front.signature.members
    assert set(members) == {"pixels", "beats", "maps", "right_beats", "right_maps"}
    assert members["beats"] == own.signature.members["beats"]
    assert members["maps"] == own.signature.members["maps"]
    assert members["right_beats"] == right.signature.members["beats"]
    assert members["right_maps"] == right.signature.members["maps"] == own.signature.members["right_maps"]
    assert members["maps"] == wiring.In(map_stream(p))
    with pytest.raises(ValueError, match="a pass's name makes its port's name"):
        StereoSignature(p, {"right pass": rp})


def test_the_front_end_and_the_emulated_machine_use_the_declared_streams() -> None:
    p, model = _params(), ModelParams(name="paper", dmax=DMAX)
    assert WordGenerator(params=p, model=model).signature.members["beats"].signature == load_stream(p)
    assert FrontEnd(params=p, model=model, width=20).signature.members["beats"].signature == load_stream(p)
    smtj = _params("smtj")
    emulated = SMTJEmulatedMachine(params=smtj)
    assert emulated.signature == MachineSignature(smtj, entropy=False)
    assert emulated.signature.members["load"].signature == load_stream(smtj).flip()
    assert emulated.signature.members["result"].signature == result_stream(smtj)
    assert SMTJEmulator(params=smtj).signature.members["numbers"].shape == entropy_layout(smtj)


@pytest.mark.parametrize("rng", ["lfsr", "lfsr-shared", "sobol"])
def test_on_chip_sources_implement_one_interface(rng: str) -> None:
    p = _params(rng)
    groups = list(range(p.operators))
    source = random_source(p, groups)
    assert isinstance(source, OnChipSource)
    assert len(source.operator_numbers) == p.operators
    assert source.shared == (rng != "lfsr")  # one number per column: read by every row
    for name in ("numbers", "next_numbers", "restart_numbers", "following_numbers",
                 "following_restart_numbers"):
        assert len(getattr(source, name)) == max(source.operator_numbers) + 1
    width = p.operators if rng == "lfsr" else 1
    assert len(source.enable) == len(source.restart) == width
    Fragment.get(source, None)  # it elaborates on its own (and is not left unused)
    assert random_source(_params("smtj")) is None


def test_an_on_chip_source_must_declare_the_interface() -> None:
    class NoRestart(OnChipSource):
        def __init__(self) -> None:
            super().__init__({"enable": wiring.In(1)}, operator_numbers=[0])

    with pytest.raises(TypeError, match="restart"):
        NoRestart()
    with pytest.raises(ParameterError, match="operator_numbers"):
        LFSRBank(specs=lfsr_specs(_params()), operator_numbers=[0, 10_000])
    with pytest.raises(ParameterError, match="one enable"):
        specs = lfsr_specs(_params())
        LFSRBank(specs=specs[:2], enable_groups=[0, 1], operator_numbers=[0, 0, 1])


def test_components_take_keyword_arguments_only() -> None:
    p, model = _params(), ModelParams(name="paper", dmax=DMAX)
    for build in (
        lambda: BayesianMachine(p),
        lambda: ParallelMachines(p, 2),
        lambda: StereoMachine(p, model, 20),
        lambda: FrontEnd(p, model, 20),
        lambda: WordGenerator(p, model),
        lambda: LineBuffer(8),
        lambda: MAPEncoder(4),
        lambda: OperatorMatrix(2, 1, 4, [0, 1]),
        lambda: SobolGenerators(_params("sobol")),
        lambda: LFSRBank(lfsr_specs(p)),
        lambda: SMTJEmulatedMachine(_params("smtj")),
        lambda: SMTJEmulator(_params("smtj")),
    ):
        with pytest.raises(TypeError, match="positional"):
            build()


def test_components_raise_type_error_for_a_wrong_type_and_value_error_for_a_wrong_value() -> None:
    p, model = _params(), ModelParams(name="paper", dmax=DMAX)
    with pytest.raises(TypeError, match="MachineParams"):
        BayesianMachine(params=p.to_dict())  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="machines"):
        ParallelMachines(params=p, machines=2.0)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="machines"):
        ParallelMachines(params=p, machines=0)
    with pytest.raises(TypeError, match="model"):
        WordGenerator(params=p, model={"dmax": DMAX})  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="params"):
        FrontEnd(params=None, model=model, width=20)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="width"):
        LineBuffer(width="8")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="width"):
        LineBuffer(width=1)
    with pytest.raises(TypeError, match="rows"):
        MAPEncoder(rows=4.0)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="nomatch_row"):
        MAPEncoder(rows=4, nomatch_row=1)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="sources"):
        OperatorMatrix(rows=2, columns=1, word_bits=4, sources=3)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="specs"):
        LFSRBank(specs=lfsr_specs(p)[0])  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="smtj"):
        SMTJEmulatedMachine(params=p)
    with pytest.raises(TypeError, match="MachineParams"):
        SMTJEmulatedMachine(params=None)  # type: ignore[arg-type]


def test_component_parameters_are_read_only() -> None:
    p, model = _params(), ModelParams(name="paper", dmax=DMAX)
    for component, names in (
        (BayesianMachine(params=p), ("params",)),
        (ParallelMachines(params=p, machines=2), ("params", "machines")),
        (StereoMachine(params=p, model=model, width=20), ("params", "model", "width", "fifo_pixels")),
        (FrontEnd(params=p, model=model, width=20), ("params", "model", "width")),
        (WordGenerator(params=p, model=model), ("params", "model", "tables")),
        (LineBuffer(width=8), ("width",)),
        (MAPEncoder(rows=4), ("rows", "nomatch_row", "tie_break")),
        (OperatorMatrix(rows=2, columns=1, word_bits=4, sources=[0, 1]),
         ("rows", "columns", "word_bits", "sources")),
        (SMTJEmulatedMachine(params=_params("smtj")), ("params",)),
        (LFSRBank(specs=lfsr_specs(p)), ("specs", "enable_groups", "operator_numbers")),
        (FeatureFilter(), ()),
    ):
        for name in names:
            value = getattr(component, name)
            with pytest.raises(AttributeError):
                setattr(component, name, value)
