# amaranth: UnusedElaboratable=no
"""The one rule for a parameter's value (bayesmachine/checks.py) across the public constructors:
NumPy integer and bool scalars accepted as Python's operator.index takes them (bools as bools, never as
numbers), plain Python values kept, huge integers refused without an OverflowError, keyword arguments
only, TypeError for a type and ParameterError naming the parameter for a value."""

from __future__ import annotations

import numpy as np
import pytest

from bayesmachine.checks import as_bool, as_int, as_real, plain
from bayesmachine.errors import ParameterError
from bayesmachine.host.calib import StereoCalibration
from bayesmachine.host.confidence import ConfidenceParams
from bayesmachine.models import ModelParams, check_disparity_machine, disparity_machine, pass_machine
from bayesmachine.params import MachineParams, nth_machine

HUGE = 10**400  # float(HUGE) is an OverflowError


def test_the_rule() -> None:
    assert as_int("n", np.uint8(7)) == 7 and type(as_int("n", np.int64(7))) is int
    assert as_bool("b", np.True_) is True and as_real("x", np.float32(0.5)) == 0.5
    assert plain(np.int64(3)) == 3 and type(plain(np.float32(0.5))) is float and plain("s") == "s"
    for bad in (True, np.False_, 1.0, "1", None):
        with pytest.raises(TypeError, match="n must be an integer, not"):
            as_int("n", bad)
    for bad in (1, 0, "yes", None):
        with pytest.raises(TypeError, match="b must be True or False, not"):
            as_bool("b", bad)
    digits = r"^n must be an integer in \[0, 3\], got an integer of 401 digits"
    with pytest.raises(ParameterError, match=digits) as e:
        as_int("n", HUGE, 0, 3)
    assert e.value.parameter == "n"
    for value in (HUGE, -HUGE, float("nan"), float("inf")):
        with pytest.raises(ParameterError, match="x must be a finite number"):
            as_real("x", value)
    with pytest.raises(ParameterError, match=r"x must be a finite number in \[1, 1e\+06\] pixels, got 1e\+0"):
        as_real("x", 1e7, 1, 1e6, " pixels")


# Every public parameter object: a NumPy scalar for each kind of field, read back as a Python value.
NUMPY_FIELDS = [
    (lambda: MachineParams(rows=np.int64(10), columns=np.uint8(3), counter_max=np.int32(4),
                           nomatch_row=np.True_, normalize=np.bool_(True), seed=np.uint64(2**63)),
     {"rows": 10, "columns": 3, "counter_max": 4, "nomatch_row": True, "normalize": True, "seed": 2**63}),
    (lambda: MachineParams.for_disparity(np.int16(8), samples_per_clock=np.int64(4), max_cycles=np.int64(99)),
     {"rows": 10, "samples_per_clock": 4, "max_cycles": 99}),
    (lambda: MachineParams.for_disparity(8, rng="smtj", smtj_dwell=np.float32(2.5), smtj_spread=np.int64(0)),
     {"smtj_dwell": 2.5, "smtj_spread": 0.0}),
    (lambda: ModelParams(name="census", dmax=np.int64(8), census_window=np.int64(5), neighbour_prior=np.True_,
                         census_p0=np.float64(0.1), prior_s=np.float32(2.0)),
     {"dmax": 8, "census_window": 5, "neighbour_prior": True, "census_p0": 0.1, "prior_s": 2.0}),
    (lambda: ConfidenceParams(t=np.int64(3), window=np.uint16(5)), {"t": 3, "window": 5}),
    (lambda: StereoCalibration(fx=np.float32(700), fy=np.int64(700), cx=300, cy=200, baseline=np.float64(0.5),
                               width=np.int64(640), height=np.uint16(480)),
     {"fx": 700.0, "fy": 700.0, "baseline": 0.5, "width": 640, "height": 480}),
]


@pytest.mark.parametrize("make, want", NUMPY_FIELDS)
def test_numpy_scalars_are_accepted_and_kept_as_python_values(make, want) -> None:
    obj = make()
    for name, value in want.items():
        got = getattr(obj, name)
        assert got == value and type(got) is type(value), (name, got)
    if isinstance(obj, MachineParams):
        assert obj == MachineParams(**{f: getattr(obj, f) for f in obj.to_dict(complete=True)})
    if isinstance(obj, ModelParams):
        assert obj.to_dict() == ModelParams(**obj.to_dict()).to_dict()  # JSON-ready, no np types inside


@pytest.mark.parametrize("make, message", [
    (lambda: MachineParams(rows=True), "rows must be an integer, not bool True"),
    (lambda: MachineParams(rows=10, columns=np.True_), "columns must be an integer, not bool"),
    (lambda: MachineParams(rows=10, normalize=1), "normalize must be True or False, not int 1"),
    (lambda: MachineParams(rows=10, nomatch_row="yes"), "nomatch_row must be True or False"),
    (lambda: MachineParams(rows=10, rng=1), r"rng must be a random source's name \(str\), not int 1"),
    (lambda: MachineParams(rows=10, rng="smtj", smtj_dwell=True), "smtj_dwell must be a number, not bool"),
    (lambda: ModelParams(name="census", census_window=7.0), "census_window must be an integer, not float"),
    (lambda: ModelParams(name="census", neighbour_prior=1), "neighbour_prior must be True or False, not int"),
    (lambda: ModelParams(name="paper", p0="0.1"), "p0 must be a number, not str"),
    (lambda: ConfidenceParams(t=2.0), "t must be an integer, not float"),
    (lambda: StereoCalibration(fx=1, fy=1, cx=0, cy=0, baseline=1, width=640.0), "width must be an integer"),
    (lambda: disparity_machine("census"),
     r"model must be a ModelParams \(e.g. ModelParams\(name='census'\)\), not str 'census'"),
    (lambda: pass_machine("census-lr", None, "right"), "model must be a ModelParams"),
    (lambda: check_disparity_machine(ModelParams(name="paper", dmax=4), "m"),
     "machine must be a MachineParams"),
])
def test_a_wrong_type_is_a_type_error_that_says_what_it_takes(make, message) -> None:
    with pytest.raises(TypeError, match=message):
        make()


@pytest.mark.parametrize("make, parameter", [
    (lambda: ModelParams(name="paper", p0=HUGE), "p0"),  # was OverflowError
    (lambda: ModelParams(name="paper", sigma_m=HUGE), "sigma_m"),
    (lambda: ModelParams(name="census", census_sigma=-HUGE), "census_sigma"),
    (lambda: ModelParams(name="census-lr", lr_beta=HUGE), "lr_beta"),
    (lambda: ModelParams(name="census", census_window=HUGE), "census_window"),
    (lambda: ModelParams(name="paper", dmax=HUGE), "dmax"),
    (lambda: MachineParams(rows=HUGE), "rows"),
    (lambda: MachineParams.for_disparity(8, rng="smtj", smtj_dwell=HUGE), "smtj_dwell"),
    (lambda: MachineParams.for_disparity(8, columns=HUGE), "columns"),
    (lambda: nth_machine(MachineParams.for_disparity(4), -HUGE), "index"),
    (lambda: ConfidenceParams(t=2**64), "t"),
    (lambda: ConfidenceParams(window=9223372036854775807), "window"),  # wrapped in int64, every confidence 0
    (lambda: StereoCalibration(fx=HUGE, fy=1, cx=0, cy=0, baseline=1), "fx"),  # was OverflowError
    (lambda: StereoCalibration(fx=1, fy=1, cx=0, cy=0, baseline=1, height=HUGE), "height"),
    (lambda: MachineParams.for_disparity(8, rng="bogus"), "rng"),  # its parameter was None
])
def test_an_impossible_value_is_a_parameter_error_naming_it(make, parameter) -> None:
    with pytest.raises(ParameterError) as info:
        make()
    assert info.value.parameter == parameter and parameter in str(info.value)


@pytest.mark.parametrize("make", [
    lambda: MachineParams(10, 3),
    lambda: ModelParams("census"),
    lambda: ConfidenceParams(2, 3),
    lambda: StereoCalibration(700, 700, 300, 200, 0.5),
])
def test_public_constructors_take_keyword_arguments_only(make) -> None:
    with pytest.raises(TypeError, match="positional"):
        make()


def test_the_hardware_and_engine_constructors_take_numpy_integers_too() -> None:
    """'machines must be an integer, not int64': the components and engines read integers by the same
    rule (their values plain ints)."""
    from bayesmachine.fpga.boards.status import ReceiveTimeout
    from bayesmachine.fpga.boards.uart import check_clocks_per_bit
    from bayesmachine.hdl.machine.encoder import MAPEncoder
    from bayesmachine.hdl.machines import ParallelMachines
    from bayesmachine.region import OutputRegion
    from bayesmachine.sim.machines import ParallelMachinesModel

    params = MachineParams.for_disparity(4, rng="lfsr")
    assert ParallelMachines(params=params, machines=np.int64(2)).machines == 2
    assert MAPEncoder(rows=np.uint8(6)).rows == 6
    assert len(ParallelMachinesModel(params, np.int32(3))._models) == 3
    assert type(OutputRegion(12, 20, 1, np.int64(3)).margin) is int
    assert check_clocks_per_bit(np.int64(8)) == 8 and ReceiveTimeout(cycles=np.int64(9))
    for make in (lambda: ParallelMachines(params=params, machines=np.True_), lambda: MAPEncoder(rows=6.0)):
        with pytest.raises(TypeError, match="must be an integer, not (bool|float)"):
            make()


# --- The on-chip front end reads its parameters by the same rule ---

def _front_end(name: str, **given: object) -> object:
    """The front-end component ``name`` with its parameters at valid values, ``given`` replacing them."""
    from bayesmachine.hdl.frontend.census import CensusFilter
    from bayesmachine.hdl.frontend.filters import FeatureFilter
    from bayesmachine.hdl.frontend.lanes.consistency import ConsistencyTest
    from bayesmachine.hdl.frontend.layouts import features_layout
    from bayesmachine.hdl.frontend.linebuffer import LineBuffer
    from bayesmachine.hdl.frontend.passes import PassFeeder
    from bayesmachine.hdl.frontend.stereo import StereoMachine, stereo_machine_params
    from bayesmachine.hdl.frontend.words import WordGenerator

    model = ModelParams(name="census", dmax=4)
    params = stereo_machine_params(4, model=model)
    kinds = {
        "census": (CensusFilter, {"window": 7}),
        "filter": (FeatureFilter, {"lag": 1}),
        "line": (LineBuffer, {"width": 20, "height": 5}),
        "consistency": (ConsistencyTest, {"dmax": 4, "map_width": 4, "tolerance": 1}),
        "feeder": (PassFeeder, {"reference": "right", "dmax": 4, "features": features_layout(model)}),
        "words": (WordGenerator, {"params": params, "model": model, "output_columns": 6, "leads": True}),
        "stereo": (StereoMachine, {"params": params, "model": model, "width": 20, "fifo_pixels": 2,
                                   "machines": 2}),
    }
    kind, kwargs = kinds[name]
    return kind(**{**kwargs, **given})


FRONT_END_NUMPY = [("census", "window", np.int64(5), 5), ("filter", "lag", np.uint8(0), 0),
                   ("line", "width", np.int32(12), 12), ("line", "height", np.int16(7), 7),
                   ("consistency", "tolerance", np.int64(2), 2), ("feeder", "dmax", np.int64(4), 4),
                   ("words", "output_columns", np.int64(6), 6), ("words", "leads", np.False_, False),
                   ("stereo", "width", np.int64(21), 21), ("stereo", "fifo_pixels", np.uint16(3), 3),
                   ("stereo", "machines", np.int32(3), 3)]


@pytest.mark.parametrize(("component", "name", "value", "want"), FRONT_END_NUMPY)
def test_the_front_end_takes_numpy_scalars_as_plain_values(component, name, value, want) -> None:
    got = getattr(_front_end(component, **{name: value}), name)
    assert got == want and type(got) is type(want)


@pytest.mark.parametrize(("component", "name", "value", "message"), [
    ("census", "window", 7.0, "window must be an integer, not float 7.0"),
    ("filter", "lag", True, "lag must be an integer, not bool True"),
    ("line", "height", "5", "height must be an integer, not str '5'"),
    ("consistency", "map_width", np.True_, "map_width must be an integer, not bool"),
    ("feeder", "dmax", 4.0, "dmax must be an integer, not float"),
    ("words", "output_columns", 6.0, "output_columns must be an integer, not float"),
    ("words", "leads", 1, "leads must be True or False, not int 1"),
    ("stereo", "width", 20.0, "width must be an integer, not float"),
    ("stereo", "fifo_pixels", True, "fifo_pixels must be an integer, not bool"),
    ("stereo", "machines", "2", "machines must be an integer, not str"),
])
def test_a_wrong_type_for_the_front_end_is_a_type_error(component, name, value, message) -> None:
    with pytest.raises(TypeError, match=f"^{message}"):
        _front_end(component, **{name: value})


@pytest.mark.parametrize(("component", "name", "value"), [
    ("census", "window", 6), ("filter", "lag", 2), ("line", "width", 1), ("line", "height", 2),
    ("consistency", "map_width", 17), ("feeder", "dmax", -1), ("feeder", "dmax", HUGE),
    ("stereo", "width", 10), ("stereo", "fifo_pixels", 65), ("stereo", "machines", 17),
])
def test_an_impossible_value_for_the_front_end_is_a_parameter_error_naming_it(component, name, value) -> None:
    with pytest.raises(ParameterError) as info:
        _front_end(component, **{name: value})
    assert info.value.parameter == name and str(info.value).startswith(name)


# --- The machine's, the board's, the formal wrappers' and the devices' parameters: the same rule ---

def _parts() -> dict[str, object]:
    from bayesmachine.fpga.boards import protocol as pr
    from bayesmachine.fpga.boards.arbiter import TransmitArbiter
    from bayesmachine.fpga.boards.build import uart_clocks_per_bit
    from bayesmachine.fpga.boards.serializer import ResultSerializer
    from bayesmachine.hdl.formal.counter import CounterProperties
    from bayesmachine.hdl.formal.runner import sby_text
    from bayesmachine.hdl.machine.encoder import MAPEncoder
    from bayesmachine.hdl.signatures import MachineSignature
    from bayesmachine.sources.smtj import TelegraphBank

    params = MachineParams.for_disparity(4, rng="lfsr")
    return {
        "pass_tag": lambda v: pr.pass_tag(v),
        "arbiter": lambda v: len(TransmitArbiter(results=v).results),
        "serializer": lambda v: ResultSerializer(params=params, tag=v).tag,
        "baud": lambda v: uart_clocks_per_bit(25.0, v),
        "counter": lambda v: CounterProperties(n_max=v).n_max,
        "depth": lambda v: sby_text("bmc", v).split("depth ")[1].split()[0],
        "encoder": lambda v: MAPEncoder(rows=6, nomatch_row=v).nomatch_row,
        "signature": lambda v: sorted(MachineSignature(params, entropy=v).members),
        "devices": lambda v: TelegraphBank(v, 3.0).devices,
        "spread": lambda v: TelegraphBank(2, 3.0, spread=v).tau.tolist(),
    }


@pytest.mark.parametrize(("part", "value", "plain_value"), [
    ("pass_tag", np.int64(1), 1), ("arbiter", np.uint8(2), 2), ("serializer", np.int32(ord("a")), ord("a")),
    ("baud", np.int64(115200), 115200), ("counter", np.int16(3), 3), ("depth", np.int64(7), 7),
    ("encoder", np.True_, True), ("signature", np.True_, True), ("devices", np.int64(3), 3),
    ("spread", np.float32(0.25), 0.25),
])
def test_numpy_scalars_are_taken_as_their_python_values(part, value, plain_value) -> None:
    read = _parts()[part]
    assert read(value) == read(plain_value)


@pytest.mark.parametrize(("part", "value", "message"), [
    ("pass_tag", 1.0, "index must be an integer, not float"),
    ("arbiter", True, "results must be an integer, not bool"),
    ("serializer", "R", "tag must be an integer, not str"),
    ("baud", 9600.0, "baud must be an integer, not float"),
    ("counter", 2.0, "n_max must be an integer, not float"),
    ("depth", True, "depth must be an integer, not bool"),
    ("encoder", 1, "nomatch_row must be True or False, not int 1"),
    ("signature", 0, "entropy must be True or False, not int 0"),
    ("devices", 2.0, "devices must be an integer, not float"),
    ("spread", "0.1", "spread must be a number, not str"),
])
def test_a_wrong_type_is_a_type_error_in_every_part(part, value, message) -> None:
    with pytest.raises(TypeError, match=f"^{message}"):
        _parts()[part](value)


@pytest.mark.parametrize(("part", "value", "parameter"), [
    ("pass_tag", 9, "index"), ("arbiter", 10, "results"), ("serializer", 5, "tag"), ("baud", 0, "baud"),
    ("counter", 0, "n_max"), ("depth", 0, "depth"), ("devices", 0, "devices"), ("spread", 1.5, "spread"),
])
def test_an_impossible_value_is_a_parameter_error_naming_it_in_every_part(part, value, parameter) -> None:
    with pytest.raises(ParameterError) as info:
        _parts()[part](value)
    assert info.value.parameter == parameter and parameter in str(info.value)
