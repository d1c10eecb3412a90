"""The NumPy machine model against its parts' twins and against cases with known answers."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from bayesmachine import MachineParams, ParameterError
from bayesmachine.params import RNG_KINDS
from bayesmachine.sim.model import MachineModel, MachineResult
from bayesmachine.sources import SOURCE_KINDS, source_kind
from bayesmachine.sources.lfsr import column_lfsr_specs, lfsr_numbers, lfsr_specs
from bayesmachine.sources.sobol import SobolTwin


def _random_words(params: MachineParams, pixels: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    one = params.word_one
    words = rng.integers(0, one + 1, size=(pixels, params.rows, params.operator_columns))
    # Edge words: exact 0 and exact 1 must appear.
    words[rng.random(words.shape) < 0.1] = 0
    words[rng.random(words.shape) < 0.2] = one
    return words.astype(np.uint16)


def test_lfsr_kernel_equals_twin_via_external_numbers() -> None:
    """The compiled LFSR path and the external-number path agree when fed the twin's numbers."""
    params = MachineParams(rows=5, columns=2, word_bits=6, lfsr_bits=17, counter_max=3, words_per_beat=2,
                           seed=7,
                           rng="lfsr")
    words = _random_words(params, 60, 1)
    internal = MachineModel(params).run(words)
    total = int(internal.cycles.sum())
    numbers = np.array([list(lfsr_numbers(s, total)) for s in lfsr_specs(params)]).T
    external = MachineModel(
        MachineParams(**{**params.to_dict(), "rng": "external"})
    ).run(words, numbers=numbers)
    assert internal.equal(external)


def _twin_numbers(params: MachineParams, cycles_per_pixel: np.ndarray) -> np.ndarray:
    """Every operator's number on every compute cycle, from the source's Python twin."""
    cols = params.operator_columns
    if params.rng == "lfsr":
        return np.array([list(lfsr_numbers(s, int(cycles_per_pixel.sum()))) for s in lfsr_specs(params)]).T
    if params.rng == "lfsr-shared":
        total = int(cycles_per_pixel.sum())
        per_col = np.array([list(lfsr_numbers(s, total)) for s in column_lfsr_specs(params)]).T
    else:
        twin, rows = SobolTwin(params), []
        for k in cycles_per_pixel:
            for i in range(int(k)):
                rows.append(twin.numbers)
                twin.clock(True, i == k - 1)  # the next pixel starts as this one ends
        per_col = np.array(rows)
    return np.tile(per_col, (1, params.rows))[:, : params.rows * cols]


@pytest.mark.parametrize("rng", ["lfsr", "lfsr-shared", "sobol"])
def test_on_chip_kernels_equal_their_twins_via_external_numbers(rng: str) -> None:
    """Each compiled on-chip kernel equals the external-number path fed its source's Python twin."""
    params = MachineParams(rows=5, columns=2, word_bits=4, lfsr_bits=12, counter_max=3, words_per_beat=2,
                           seed=7,
                           rng=rng, prior="loaded")
    words = _random_words(params, 80, 3)
    internal = MachineModel(params).run(words)
    assert internal.cycles.max() > 16  # some pixels span several Sobol blocks of 2^W cycles
    numbers = _twin_numbers(params, internal.cycles)
    external = MachineModel(MachineParams(**{**params.to_dict(), "rng": "external"}))
    assert internal.equal(external.run(words, numbers=numbers))


def test_source_registry_matches_params() -> None:
    assert tuple(SOURCE_KINDS) == RNG_KINDS
    assert all(SOURCE_KINDS[k].name == k and SOURCE_KINDS[k].description for k in RNG_KINDS)
    assert source_kind("external").numbers is None and not source_kind("external").on_chip
    with pytest.raises(ParameterError, match="rng must be one of"):
        source_kind("smtj-typo")


def test_model_imports_no_amaranth() -> None:
    """The model (the definition of the machine) and the source definitions need no Amaranth."""
    code = ("import sys, bayesmachine.sim.model, bayesmachine.sources.sobol; "
            "assert not any(m == 'amaranth' or m.startswith('amaranth.') for m in sys.modules), "
            "sorted(m for m in sys.modules if m.startswith('amaranth'))")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("rng", ["lfsr", "lfsr-shared", "sobol"])
def test_chunked_runs_equal_one_run(rng: str) -> None:
    params = MachineParams.for_disparity(6, counter_max=4, words_per_beat=4, rng=rng)
    words = _random_words(params, 50, 2)
    whole = MachineModel(params).run(words)
    model = MachineModel(params)
    parts = [model.run(words[i : i + 7]) for i in range(0, 50, 7)]
    assert MachineResult.concatenate(parts, params.rows).equal(whole)
    model.reset()
    assert model.run(words).equal(whole)


@pytest.mark.parametrize("tie_break", ["nomatch-first", "lowest-index"])
def test_all_ones_overflow_together(tie_break: str) -> None:
    """p = 1 everywhere: every row overflows on cycle n_max + 1, the tie rule picks the row."""
    params = MachineParams.for_disparity(3, counter_max=5, words_per_beat=1, tie_break=tie_break)
    words = np.full((3, params.rows, 3), params.word_one, np.uint16)
    r = MachineModel(params).run(words)
    assert (r.cycles == 6).all()
    assert (r.counts == 5).all()
    expected = params.rows - 1 if tie_break == "nomatch-first" else 0
    assert (r.map == expected).all()
    assert r.nomatch.all() == (tie_break == "nomatch-first")
    assert not r.timeout.any()


def test_all_zero_words_time_out() -> None:
    params = MachineParams(rows=4, columns=3, counter_max=2, max_cycles=500, words_per_beat=4)
    words = np.zeros((2, 4, 3), np.uint16)
    r = MachineModel(params).run(words)
    assert r.timeout.all() and (r.cycles == 500).all() and (r.counts == 0).all() and (r.map == 0).all()


def test_single_certain_row_wins_and_others_never_count() -> None:
    params = MachineParams.for_disparity(8, counter_max=16, words_per_beat=8)
    words = np.zeros((4, params.rows, 3), np.uint16)
    for p, d in enumerate([0, 3, 8, 9]):
        words[p, d] = params.word_one
    r = MachineModel(params).run(words)
    assert list(r.map) == [0, 3, 8, 9]
    assert list(r.nomatch) == [False, False, False, True]
    assert (r.cycles == 17).all()
    assert (r.counts.sum(axis=1) == 16).all()


def test_loaded_prior_column_gates_rows() -> None:
    """A loaded prior of 0 silences a row even when its likelihoods are 1."""
    params = MachineParams(rows=3, columns=2, prior="loaded", counter_max=3, words_per_beat=3)
    words = np.full((1, 3, 3), params.word_one, np.uint16)
    words[0, 0, 0] = 0  # prior of row 0
    r = MachineModel(params).run(words)
    assert r.map[0] == 1 and r.counts[0, 0] == 0


def test_counts_track_probabilities() -> None:
    """Over many pixels the counters of a two-row race follow the word ratio (p_j = n_j / n_max)."""
    params = MachineParams(rows=2, columns=1, counter_max=64, words_per_beat=2, word_bits=10)
    words = np.array([[[1024], [512]]] * 400, np.uint16)
    r = MachineModel(params).run(words)
    assert (r.map == 0).mean() > 0.99
    ratio = r.counts[:, 1].mean() / 64
    # Row 1 gathers about half of row 0's 64 ones in the same cycles.
    assert abs(ratio - 0.5) < 0.02


@pytest.mark.parametrize(
    "words, message",
    [
        (np.zeros((2, 3, 3), np.uint16), "expects"),
        (np.full((2, 4, 3), 1025, np.int32), r"\[0, 1024\]"),
        (np.full((2, 4, 3), -1, np.int32), r"\[0, 1024\]"),
        (np.full((2, 4, 3), 0.5), "integers"),
    ],
)
def test_bad_words_are_clear_errors(words: np.ndarray, message: str) -> None:
    model = MachineModel(MachineParams(rows=4, columns=3, words_per_beat=4))
    with pytest.raises(ValueError, match=message):
        model.run(words)


def test_external_numbers_must_cover_the_run() -> None:
    params = MachineParams(rows=2, columns=1, rng="external", counter_max=2, words_per_beat=1)
    words = np.zeros((1, 2, 1), np.uint16)
    with pytest.raises(ValueError, match="ran out"):
        MachineModel(params).run(words, numbers=np.zeros((10, 2), np.uint16))


def test_small_disparity_machines_get_a_load_stream_no_wider_than_a_pixel() -> None:
    assert MachineParams.for_disparity(0).words_per_beat == 6
    assert MachineParams.for_disparity(3, prior="loaded").words_per_beat == 16
    assert MachineParams.for_disparity(2, prior="loaded").words_per_beat == 16
    assert MachineParams.for_disparity(1, prior="loaded").words_per_beat == 12
    assert MachineParams.for_disparity(80).words_per_beat == 16


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"rows": 0}, "rows"),
        ({"rows": 4, "word_bits": 0}, "word_bits"),
        ({"rows": 4, "word_bits": 16}, r"word_bits must be in \[1, 15\]"),
        ({"rows": 4, "counter_max": 0}, "counter_max"),
        ({"rows": 4, "rng": "trng"}, "rng"),
        ({"rows": 4, "word_bits": 10, "lfsr_bits": 11}, "lfsr_bits"),
        ({"rows": 4, "counter_max": 100, "max_cycles": 100}, "max_cycles"),
        ({"rows": 4, "words_per_beat": 13}, "words_per_beat"),
        ({"rows": 1, "nomatch_row": True}, "no-match"),
        ({"rows": 4, "tie_break": "random"}, "tie_break"),
    ],
)
def test_impossible_parameters_name_the_problem(kwargs: dict, message: str) -> None:
    with pytest.raises(ParameterError, match=message) as err:
        MachineParams(**kwargs)
    assert err.value.parameter is None or err.value.parameter in kwargs or err.value.parameter == "rows"


@pytest.mark.parametrize("kwargs, name", [({"rows": 4.0}, "rows"), ({"rows": 4, "seed": "1"}, "seed"),
                                          ({"rows": 4, "prior": 1}, "prior"), ({"rows": True}, "rows")])
def test_wrong_types_are_type_errors(kwargs: dict, name: str) -> None:
    with pytest.raises(TypeError, match=f"^{name}"):
        MachineParams(**kwargs)


def test_device_parameters_belong_to_the_smtj_source() -> None:
    """``MachineParams(rng="sobol", smtj_dwell=5)`` is refused as the command line refuses it."""
    with pytest.raises(ParameterError, match="^smtj_dwell: device parameters of rng 'smtj'") as err:
        MachineParams(rows=4, rng="sobol", smtj_dwell=5, words_per_beat=3)
    assert err.value.parameter == "smtj_dwell"
    plain = MachineParams(rows=4, rng="sobol", words_per_beat=3)
    assert plain.smtj_dwell is None and "smtj_dwell" not in plain.to_dict()
    smtj = MachineParams(rows=4, rng="smtj", words_per_beat=3)
    assert (smtj.smtj_dwell, smtj.smtj_spread, smtj.smtj_share) == (1.0, 0.0, "operator")
    assert MachineParams(**smtj.to_dict()) == smtj


def test_params_run_the_sources_own_checks() -> None:
    """One validation path: a MachineParams is a machine whose random source can be built (the
    source registry's check runs as the last step of MachineParams validation)."""
    # L = 12, W = 10: taps <= 2 leave no primitive polynomial; only on-chip kinds need one.
    for rng in ("lfsr", "lfsr-shared", "sobol"):  # sobol's digital shifts come from column LFSRs
        with pytest.raises(ParameterError, match="lfsr_bits = 12: no primitive LFSR polynomial"):
            MachineParams.for_disparity(4, rng=rng, lfsr_bits=12)
    for rng in ("external", "smtj"):
        assert MachineParams.for_disparity(4, rng=rng, lfsr_bits=12).lfsr_bits == 12
    # The Sobol table holds 16 dimensions: one per operator column, a loaded prior's included.
    with pytest.raises(ParameterError, match="at most 16 operator columns .* has 17"):
        MachineParams(rows=2, columns=16, rng="sobol", prior="loaded", words_per_beat=2)
    assert MachineParams(rows=2, columns=16, rng="lfsr", prior="loaded",
                         words_per_beat=2).operator_columns == 17
    with pytest.raises(ParameterError, match="rng must be one of lfsr, lfsr-shared, sobol, external, smtj"):
        MachineParams(rows=4, rng="sobol2")
    with pytest.raises(TypeError, match=r"rng must be a random source's name \(str\), not list"):
        MachineParams(rows=4, rng=["sobol"])  # type: ignore[arg-type]


def test_sources_do_not_import_params_at_run_time() -> None:
    """params imports the source registry at module level; a source module imports params only for
    type checking (or inside a function), so there is no import cycle between them."""
    import ast
    from pathlib import Path

    import bayesmachine.sources as sources

    for path in sorted(Path(sources.__file__).parent.glob("*.py")):
        for node in ast.parse(path.read_text()).body:  # module level; `if TYPE_CHECKING:` is an If
            names = ([node.module or ""] if isinstance(node, ast.ImportFrom)
                     else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
            assert "bayesmachine.params" not in names, f"{path.name} imports bayesmachine.params"
    code = "import bayesmachine.sources.sobol, bayesmachine.sources.lfsr, bayesmachine.sources.smtj"
    subprocess.run([sys.executable, "-c", code], check=True)
    # The parameters stay light: the registry they validate through needs no NumPy.
    code = "import sys, bayesmachine.params; assert 'numpy' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_front_end_lanes_are_defined_once() -> None:
    from bayesmachine.hdl.frontend import stereo
    from bayesmachine.models import ModelParams, disparity_machine
    from bayesmachine.params import stereo_words_per_beat

    assert stereo.stereo_words_per_beat is stereo_words_per_beat
    # 6 rows of the operator columns per beat: 18 words, 14 beats per pixel at Dmax 80.
    p = stereo.stereo_machine_params(80, model=ModelParams(name="paper"))
    assert (p.words_per_beat, p.beats_per_pixel) == (18, 14)
    assert stereo_words_per_beat(MachineParams.for_disparity(80, prior="loaded")) == 24
    assert stereo_words_per_beat(MachineParams.for_disparity(2)) == 4 * 3  # fewer rows than 6: all of them
    # A neighbour machine's feedback column is formed on chip: 6 rows of its 5 loaded columns.
    census = disparity_machine(ModelParams(name="census", fuse_columns=False))
    assert census.operator_columns == 6 and stereo_words_per_beat(census) == 30
