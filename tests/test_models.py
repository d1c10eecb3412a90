"""The models (bayesmachine/models.py): a model's parameters, its dict and ``replace``, and the machine
it needs (``disparity_machine``, ``check_disparity_machine``), census-lr's passes and watchdogs."""

import pytest
from columns.test_census import census_pair
from columns.test_consistency import DMAX, right_machine

from bayesmachine.columns import AbovePrior, Census
from bayesmachine.host.features import Planes
from bayesmachine.host.likelihoods import memory_words
from bayesmachine.models import (
    CENSUS_WATCHDOG_RUNS,
    RIGHT_WATCHDOG_RUNS,
    ModelParams,
    check_disparity_machine,
    disparity_machine,
    machine_layout,
)
from bayesmachine.params import MachineParams, ParameterError

PAPER_KEYS = ["dmax", "name", "p0", "sigma_m", "sigma_gh", "sigma_gv", "gradient_magnitude", "sigma_g",
              "p_nm0", "sigma_nm"]


def test_paper_model_has_its_parameters_only_and_dicts_round_trip():
    paper = ModelParams(name="paper")
    assert list(paper.to_dict()) == PAPER_KEYS
    assert ModelParams(**paper.to_dict()) == paper  # the name too: ModelParams() is another model
    assert paper.column(Census) is None and machine_layout(paper.columns) == ("uniform", 3)
    with pytest.raises(AttributeError, match="census_window"):
        paper.census_window  # noqa: B018
    with pytest.raises(ParameterError, match="^census_window is not a parameter of the paper model"):
        ModelParams(name="paper", census_window=5)
    with pytest.raises(TypeError, match="census_widow"):
        ModelParams(name="census", census_widow=5)
    census = ModelParams(name="census", census_window=5)
    d = census.to_dict()
    assert d["name"] == "census" and d["census_sigma"] == 3.0 and d["census_nomatch_h"] == 3
    assert ModelParams(**d) == census and hash(ModelParams(**d)) == hash(census)


def test_replace_keeps_the_given_parameters_and_resolves_the_others():
    import pickle

    m = ModelParams(name="census", prior_s=3.0)
    five = m.replace(census_window=5)
    assert (five.census_window, five.census_sigma, five.census_nomatch_h, five.prior_s) == (5, 3.0, 3, 3.0)
    assert pickle.loads(pickle.dumps(m)).replace(census_window=5) == five
    # Another model: its own defaults (census-lr's no-match prior factor is its own, not census's).
    assert ModelParams(name="census-lr").replace(name="census") == ModelParams(name="census")
    assert ModelParams(name="census", census_window=5).replace(name="paper") == ModelParams(name="paper")


def test_disparity_machine_builds_the_model_s_machine():
    paper = ModelParams(name="paper", dmax=6)
    assert disparity_machine(paper, counter_max=4) == MachineParams.for_disparity(6, counter_max=4)
    no_prior = ModelParams(dmax=6, name="census", fuse_columns=False, neighbour_prior=False)
    assert disparity_machine(no_prior) == MachineParams.for_disparity(
        6, columns=4, timeout_answer="leading", normalize=True, max_cycles=CENSUS_WATCHDOG_RUNS * 17)
    census = ModelParams(dmax=80, name="census", fuse_columns=False)
    m = disparity_machine(census, word_bits=10)
    q = census.column(AbovePrior).table(10)
    assert m.prior == "neighbour" and m.columns == 4
    assert m.feedback_words == tuple(int(v) for v in q.values[: q.last_change() + 1])
    assert m.feedback_nomatch_word == q.nomatch[0] == 641
    # The clamped table gives every |d - d_n| the full table's word.
    for k in range(81):
        assert m.feedback_words[min(k, len(m.feedback_words) - 1)] == q.values[k]
    # Loading stays hidden at counter max 16: no run is shorter than n_max + 1 = 17 cycles.
    assert (m.words_per_beat, m.words_per_pixel, m.beats_per_pixel) == (30, 410, 14)
    assert m.beats_per_pixel <= 17 - 1
    # A different word width gives its own table; contradicting fields are refused.
    assert disparity_machine(census, word_bits=8).feedback_words != m.feedback_words
    with pytest.raises(ParameterError, match="^prior: .*'neighbour'"):
        disparity_machine(census, prior="loaded")
    with pytest.raises(ParameterError, match="^columns: "):
        disparity_machine(census, columns=3)
    with pytest.raises(ParameterError, match="^feedback_words: "):
        disparity_machine(census, feedback_words=(1024, 3))
    with pytest.raises(ParameterError, match="^prior: 'neighbour'"):
        disparity_machine(no_prior, prior="neighbour")
    with pytest.raises(ParameterError, match="^prior: 'neighbour'"):
        disparity_machine(paper, prior="neighbour")
    assert disparity_machine(census, prior="neighbour", words_per_beat=7).words_per_beat == 7
    # A pixel's words in one beat: the loaded above column counts (the probe for the word width without
    # it refused more than the data columns' words, 328 here).
    whole = disparity_machine(census, words_per_beat=410)
    assert (whole.words_per_pixel, whole.beats_per_pixel) == (410, 1)
    with pytest.raises(ParameterError, match=r"^words_per_beat \(411\) exceeds the words per pixel \(410\)"):
        disparity_machine(census, words_per_beat=411)


def test_machine_checks_are_one_function():
    census = ModelParams(dmax=6, name="census", fuse_columns=False)
    no_prior = ModelParams(dmax=6, name="census", fuse_columns=False, neighbour_prior=False)
    with pytest.raises(ParameterError, match="^columns: .*4 data columns"):
        check_disparity_machine(no_prior, MachineParams.for_disparity(6))
    with pytest.raises(ParameterError, match="^rows: .*for_disparity"):
        check_disparity_machine(no_prior, MachineParams.for_disparity(7, columns=4))
    with pytest.raises(ParameterError, match="^neighbour_prior .*prior='neighbour'.*disparity_machine"):
        check_disparity_machine(census, MachineParams.for_disparity(6, columns=4))
    with pytest.raises(ParameterError, match="^neighbour_prior .*prior='neighbour'"):
        check_disparity_machine(census, MachineParams.for_disparity(6, columns=4, prior="loaded"))
    # A neighbour machine with another table (another model's eps) is refused: its feedback would
    # not be the model's prior.
    other = disparity_machine(ModelParams(dmax=6, name="census", fuse_columns=False, prior_eps=0.2))
    with pytest.raises(ParameterError, match="^neighbour_prior: .*feedback table"):
        check_disparity_machine(census, other)
    # A neighbour machine with a model without the prior.
    with pytest.raises(ParameterError, match="^prior: .*with neighbour_prior off has none"):
        check_disparity_machine(no_prior, disparity_machine(census))
    with pytest.raises(ParameterError, match="^p_nm0: .*quantizes to 0"):
        check_disparity_machine(ModelParams(name="paper", dmax=6, p_nm0=1e-4),
                                MachineParams.for_disparity(6, word_bits=4))
    with pytest.raises(ParameterError, match="^census_nomatch_h = 48: .*quantizes to 0"):
        far = ModelParams(dmax=6, name="census", fuse_columns=False, census_nomatch_h=48,
                          neighbour_prior=False, p_nm0=0.5)
        check_disparity_machine(far, MachineParams.for_disparity(6, columns=4, word_bits=4))
    with pytest.raises(ParameterError, match="^prior_nomatch = 0.0001 quantizes to 0"):
        disparity_machine(ModelParams(dmax=6, name="census", fuse_columns=False, prior_nomatch=1e-4))
    assert check_disparity_machine(census, disparity_machine(census)) == 2
    assert check_disparity_machine(no_prior, MachineParams.for_disparity(6, columns=4, prior="loaded")) == 1
    fl, fr, _ = census_pair(6)
    with pytest.raises(ParameterError, match="census column needs the census"):
        bare = Planes({name: fl[name] for name in ("m25", "gh20", "gv20")})  # no census codes
        memory_words(bare, fr, no_prior, MachineParams.for_disparity(6, columns=4))


def test_model_fields_and_dict():
    m = ModelParams(name="census-lr")
    assert machine_layout(m.columns) == ("neighbour", 2) and [p.name for p in m.passes] == ["right", "left"]
    # The default model, census-sgm: census-lr's layout, its right pass census-sg's.
    default = ModelParams()
    assert default == ModelParams(name="census-sgm") and default.name == "census-sgm"
    assert machine_layout(default.columns) == machine_layout(m.columns)
    passes = [(p.name, p.model.name) for p in default.passes]
    assert passes == [("right", "census-sg"), ("left", "census-sgm")]
    right = m.pass_named("right")
    assert (right.reference, right.machine_index, right.nomatch, right.max_cycles) == ("right", 1, True, None)
    assert m.prior_nomatch == 0.1 and right.model.name == "census"
    assert right.model.prior_nomatch == pytest.approx(0.626, abs=1e-3)  # the census model's own
    d = m.to_dict()
    assert (d["lr_beta"], d["lr_gamma"], d["lr_tolerance"], d["prior_nomatch"]) == (0.1, 0.01, 1, 0.1)
    assert d["lr_nomatch"] is True and d["lr_right_nomatch"] is True and d["lr_neutral"] is True
    assert ModelParams(**d).to_dict() == d
    # The other models' dicts (reports, Verilator design keys) are what they were.
    assert not any(k.startswith("lr_") for k in ModelParams(name="census").to_dict())
    assert not any(k.startswith("lr_") for k in ModelParams(name="paper").to_dict())


def test_census_machines_default_watchdog_and_normalization():
    """The census models' machines stop a run after CENSUS_WATCHDOG_RUNS runs of n_max + 1 cycles by
    default, census-lr's right pass after RIGHT_WATCHDOG_RUNS; a given max_cycles wins (the right pass
    keeps its own unless lr_right_max_cycles gives one); both normalize their columns unless told not
    to; the paper model keeps the machine's own defaults."""
    from bayesmachine.params import DEFAULT_MAX_CYCLES, MachineParams

    lr = ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False)
    for n in (1, 8, 16):
        m = disparity_machine(lr, counter_max=n)
        assert m.max_cycles == CENSUS_WATCHDOG_RUNS * (n + 1)
        assert right_machine(lr, m).max_cycles == RIGHT_WATCHDOG_RUNS * (n + 1)
        census = disparity_machine(ModelParams(dmax=DMAX, name="census"), counter_max=n)
        assert census.max_cycles == CENSUS_WATCHDOG_RUNS * (n + 1)
    assert (CENSUS_WATCHDOG_RUNS * 17, RIGHT_WATCHDOG_RUNS * 17) == (255, 136)  # the documented figures
    m = disparity_machine(lr, counter_max=8, max_cycles=5000)
    assert m.max_cycles == 5000 and right_machine(lr, m).max_cycles == RIGHT_WATCHDOG_RUNS * 9
    assert right_machine(ModelParams(dmax=DMAX, name="census-lr", fuse_columns=False,
                                     lr_right_max_cycles=100),
                         disparity_machine(lr, counter_max=8)).max_cycles == 100
    assert m.normalize and right_machine(lr, m).normalize
    off = disparity_machine(lr, normalize=False)
    assert not off.normalize and not right_machine(lr, off).normalize
    paper = disparity_machine(ModelParams(dmax=DMAX, name="paper"), counter_max=8)
    assert paper.max_cycles == DEFAULT_MAX_CYCLES and not paper.normalize
    assert MachineParams.for_disparity(DMAX).max_cycles == DEFAULT_MAX_CYCLES
