"""A model defined outside the package: the snippet of docs/development.md ("A model of your own"),
written to a file of its own and imported, registers census-lr's columns plus the gradient-magnitude
column (five FEATURES columns) with a pass of its own, "mirror" (the right image as reference); the
library and ``bayesmachine.cli.main`` take it. Bad definitions are one error each, naming the model."""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import user_models

from bayesmachine.cli import main
from bayesmachine.columns import (
    NEIGHBOUR_PRIOR,
    AbovePrior,
    Census,
    Column,
    Consistency,
    GradH,
    GradMag,
    GradV,
    LeftPrior,
    Mean,
    Option,
    Source,
    consistency,
)
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words, pass_grid, pass_words
from bayesmachine.host.reference import declared_maps, reference_map, reference_quantized_map
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import MODELS, ModelDef, ModelParams, PassDef, disparity_machine, register_model
from bayesmachine.region import OutputRegion


@pytest.fixture(scope="module")
def user_model(tmp_path_factory: pytest.TempPathFactory):
    """The snippet, written to a file outside the package and imported; the models it registered are
    taken out of the registry afterwards (the other tests see the package's three)."""
    with user_models(tmp_path_factory.mktemp("user")):
        yield ModelParams(name="census-g-lr", dmax=8)


@pytest.fixture(scope="module")
def crop() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """22 x 60 pixels of the bundled pair, the right image 46 columns further left: disparities 0..8."""
    left, right, gt = bundled_pair()
    y, x, h, w, shift = 196, 300, 22, 60, 46
    return (np.ascontiguousarray(left[y : y + h, x : x + w]),
            np.ascontiguousarray(right[y : y + h, x - shift : x - shift + w]),
            gt[y : y + h, x : x + w] - shift)


def test_the_snippet_makes_a_model_of_five_feature_columns_and_a_fed_pass(user_model: ModelParams) -> None:
    model = user_model
    assert [c.name for c in model.columns] == ["left-prior", "above-prior", "m", "gh", "gv", "census", "g",
                                               "lr"]
    assert sum(c.source is Source.FEATURES for c in model.columns) == 5
    assert [p.name for p in model.passes] == ["mirror", "left"]
    mirror = model.pass_named("mirror")
    assert mirror.reference == "right" and mirror.model.name == "census-g" and mirror.machine_index == 1
    assert not any(name.startswith("lr_right") for name in model.definition.options)
    assert set(model.planes) == {"m25", "gh20", "gv20", "census", "g20"} and model.margin == 3
    assert model.replace(census_window=5).margin == 2
    machine = disparity_machine(model)
    assert machine.prior == "neighbour" and machine.columns == 6 and machine.normalize
    assert machine.max_cycles == 15 * 17 and machine.timeout_answer == "leading"
    assert ModelParams(name="census-g-lr", dmax=40, census_sigma=5.0).census_sigma == 5.0
    with pytest.raises(ValueError, match="gradient_magnitude is not a parameter of the census-g-lr model"):
        ModelParams(name="census-g-lr", gradient_magnitude=True)


def test_the_cli_lists_and_takes_it(user_model: ModelParams, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--help"]) == 0
    help_text = capsys.readouterr().out
    choices = re.search(r"--model \{([a-z0-9,-]+)\}", help_text)
    assert choices is not None
    assert {"census-lr", "census-g", "census-g-lr"} <= set(choices.group(1).split(","))
    assert "census-g-lr: census-g + a left-right consistency column" in " ".join(help_text.split())
    assert main(["run", "--model", "nope", "-o", "x"]) == 2
    assert "invalid choice: 'nope'" in capsys.readouterr().err


def _files(tmp_path: Path, pair: tuple[np.ndarray, np.ndarray, np.ndarray]) -> list[str]:
    left, right, gt = pair
    for name, image in (("l.png", left), ("r.png", right)):
        cv2.imwrite(str(tmp_path / name), image)
    np.save(tmp_path / "gt.npy", gt.astype(np.float64))
    return [str(tmp_path / "l.png"), str(tmp_path / "r.png")]


def test_reference_through_the_cli_is_the_librarys(user_model: ModelParams, crop, tmp_path: Path) -> None:
    files = _files(tmp_path, crop)
    assert main(["reference", *files, "--model", "census-g-lr", "--dmax", "8", "--quiet",
                 "-o", str(tmp_path / "ref.npz")]) == 0
    got = np.load(tmp_path / "ref.npz")
    left, right, gt = crop
    fl, fr = model_planes(left, user_model), model_planes(right, user_model)
    want = reference_map(fl, fr, user_model)
    np.testing.assert_array_equal(got["map"], want)
    np.testing.assert_allclose(got["posterior"].sum(axis=-1), 1.0)
    # Sensible (measured: 0.905, 0.948, 0.996): near census-lr's own reference, and within 2 of the
    # ground truth where matched.
    lr = ModelParams(name="census-lr", dmax=8)
    assert np.mean(want == reference_map(fl, fr, lr)) > 0.88
    truth = gt[3:-3, 3 + 8 : -3]
    matched = (want >= 0) & np.isfinite(truth)
    assert matched.mean() > 0.92 and np.mean(np.abs(want[matched] - truth[matched]) <= 2) > 0.98


def test_run_through_the_cli_is_the_model_engines(user_model: ModelParams, crop, tmp_path: Path) -> None:
    files = _files(tmp_path, crop)
    out = tmp_path / "run"
    assert main(["run", *files, "--gt", str(tmp_path / "gt.npy"), "--model", "census-g-lr", "--dmax", "8",
                 "--counter-max", "8", "--no-sgbm", "--quiet", "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    npz = np.load(out / "result.npz")
    model = user_model
    machine = disparity_machine(model, counter_max=8)
    assert report["model_name"] == "census-g-lr" and report["passes"] == ["mirror", "left"]
    assert report["machine"] == machine.to_dict(complete=True) and report["model"] == model.to_dict()
    left, right, gt = crop
    want = run_machine(prepare(left, right, model, gt), machine, "model", progress=False)
    for key in ("map", "cycles", "timeout"):
        np.testing.assert_array_equal(npz[key], getattr(want, key), err_msg=key)
        np.testing.assert_array_equal(npz[f"mirror_{key}"], getattr(want.passes["mirror"], key), err_msg=key)
    assert report["mirror_pass_pixels"] == want.passes["mirror"].map.size
    # Sensible (measured: 0.939, 0.004): the machine near its quantized reference (its words' exact
    # inference, 80-bit products), few bad pixels.
    fl, fr = model_planes(left, model), model_planes(right, model)
    assert np.mean(want.map == reference_quantized_map(fl, fr, model, machine.word_bits)) > 0.9
    assert report["machine_bad2"] < 0.02


def test_each_column_builds_its_own_words_from_its_source(user_model: ModelParams, crop) -> None:
    """The words of a map row: the above column from the row above's MAPs, the consistency column from
    the mirror pass's MAPs of the row, by name; the mirror pass's own words beside them."""
    model = user_model
    machine = disparity_machine(model)
    left, right, _ = crop
    fl, fr = model_planes(left, model), model_planes(right, model)
    maps = declared_maps(model, fl, fr, machine.word_bits)
    w = machine.word_bits
    region = OutputRegion.of_features(fl.shape, model.dmax)
    above = np.arange(region.shape[1]) % (model.dmax + 2) - 1  # MAPs -1 (none) .. Dmax
    words = memory_words(fl, fr, model, machine, rows=slice(4, 5), above=above,
                         results={"mirror": maps["mirror"][4:5]})
    assert words.shape == (above.size, model.hypotheses, 7)
    prior, lr = model.column(AbovePrior), model.column(Consistency)
    np.testing.assert_array_equal(words[:, :, 0], prior.loaded(prior.table(w), above))
    first = pass_grid(model.pass_named("mirror"), region).first
    np.testing.assert_array_equal(words[:, :, 6], lr.loaded(lr.table(w), maps["mirror"][4], first,
                                                            region.map_columns))
    g = words[:, :, 5]  # the g column: its table at |g_l(x) - g_r(x - d)|
    x, d = 3, 2
    table = model.column(GradMag).table(w).values
    assert g[x, d] == table[abs(int(fl.g20[4, model.dmax + x]) - int(fr.g20[4, model.dmax + x - d]))]
    mirror = model.pass_named("mirror")
    rw = pass_words(mirror, fl, fr, disparity_machine(mirror.model), rows=slice(4, 5),
                    above=maps["mirror"][3])
    assert rw.shape == (pass_grid(mirror, region).width, model.hypotheses, 6)


# --- Bad definitions: one error each, naming the model and the problem ---

FEATURES = (Mean, GradH, GradV)


class _OtherP0(Column):
    """A column declaring an option named like the paper's p0, apart from it."""

    name = "other"
    source = Source.FEATURES
    options = (Option("p0", "float", 0.5, lambda n, v, vs: None, "another p0"),)


_Nameless = consistency("nowhere", name="lr2")  # a consistency column reading a pass no model declares


@pytest.mark.parametrize(("kwargs", "error", "message"), [
    ({"columns": (Mean, "census")}, TypeError,
     r"model 'bad': columns\[1\] = 'census' is not a column kind"),
    ({"columns": (Mean, Mean)}, ValueError, "model 'bad': column m is listed twice"),
    ({"columns": (Mean, _OtherP0)}, ValueError,
     "model 'bad': option p0 is declared twice \\(by Mean and _OtherP0\\): one option, one owner"),
    ({"columns": (Mean, AbovePrior)}, ValueError,
     "model 'bad': no machine runs columns \\['m', 'above-prior'\\]"),
    ({"columns": (LeftPrior, AbovePrior, Mean), "switches": {NEIGHBOUR_PRIOR: (AbovePrior,)}}, ValueError,
     "model 'bad': no machine runs .* \\(with neighbour_prior off\\)"),
    ({"columns": (LeftPrior, AbovePrior)}, ValueError, "model 'bad': no FEATURES column"),
    ({"columns": (*FEATURES, _Nameless)}, ValueError,
     "model 'bad': column lr2 reads the results of pass 'nowhere', which the model does not declare"),
    ({"columns": FEATURES, "defaults": {"census_sigma": 3.0}}, ValueError,
     "model 'bad': defaults names 'census_sigma', not an option"),
    ({"columns": FEATURES, "passes": (PassDef(name="left", model="census", reference="right",
                                              machine_index=1),)}, ValueError,
     "model 'bad': pass name 'left'"),
    ({"columns": FEATURES, "passes": (PassDef(name="r", model="census", reference="up", machine_index=1),)},
     ValueError, "model 'bad': pass r: reference must be one of left, right, got 'up'"),
    ({"columns": FEATURES, "timeout_answer": "later"}, ValueError, "model 'bad': timeout_answer must be one"),
    # A field given one item instead of a tuple of them, a mapping as something else.
    ({"columns": Mean}, TypeError,
     r"model 'bad': columns must be a tuple \(or list\) of column kinds, got Mean$"),
    ({"columns": FEATURES, "passes": PassDef(name="r", model="census", reference="right", machine_index=1)},
     TypeError, r"model 'bad': passes must be a tuple \(or list\) of PassDef, got PassDef\(name='r'"),
    ({"columns": (LeftPrior, AbovePrior, Mean), "switches": {NEIGHBOUR_PRIOR: LeftPrior}}, TypeError,
     r"model 'bad': switches\[neighbour_prior\] must be a tuple \(or list\) of column kinds, got LeftPrior"),
    ({"columns": FEATURES, "defaults": ("p0", 0.5)}, TypeError, "model 'bad': defaults must be a mapping"),
    ({"columns": FEATURES, "requires": {"p0": 0.5}}, TypeError,
     r"model 'bad': requires\['p0'\] must be a \(value, reason\) pair, got 0.5"),
    ({"columns": FEATURES, "passes": (PassDef(name="r", model="census", reference="right", machine_index=1,
                                              not_inherited="p0"),)}, TypeError,
     r"model 'bad': pass r: not_inherited must be a tuple \(or list\) of option names, got 'p0'"),
    # A watchdog no machine counts at the default counter max (once a --max-cycles error at run time).
    ({"columns": FEATURES, "watchdog_runs": 10**12}, ValueError,
     r"model 'bad': watchdog_runs must be in \[1, 252645135\] runs of counter max \+ 1 cycles"),
    ({"columns": FEATURES, "passes": (PassDef(name="r", model="census", reference="right", machine_index=1,
                                              watchdog_runs=0),)}, ValueError,
     r"model 'bad': pass r: watchdog_runs must be in \[1, 252645135\]"),
])
def test_a_bad_definition_is_one_error(kwargs: dict, error: type, message: str) -> None:
    with pytest.raises(error, match=f"^{message}"):
        ModelDef(name="bad", description="a bad model", **kwargs)
    assert "bad" not in MODELS


@pytest.mark.parametrize("name", ["-x", "a,b", "a b", "", "1x", "x/y", "census:lr"])
def test_a_model_name_is_a_value_of_model(name: str) -> None:
    """A name that ``--model`` (or a list of models, ``sweep --model A,B``) could not take is refused
    where the model is defined: ``-x`` once registered and made ``sweep --model -x,paper`` an argparse
    error ("expected one argument")."""
    with pytest.raises(ValueError, match=f"^ModelDef: name {re.escape(repr(name))} is not a model name: a "
                       "letter, then letters, digits, '-' or '_'"):
        ModelDef(name=name, description="a model", columns=FEATURES)
    with pytest.raises(TypeError, match="^ModelDef: name must be a string, got int 3"):
        ModelDef(name=3, description="a model", columns=FEATURES)  # type: ignore[arg-type]


def test_a_model_watchdog_beyond_the_machine_names_counter_max(capsys: pytest.CaptureFixture[str]) -> None:
    """The largest watchdog_runs fits at the default counter max; a larger counter max is refused naming
    it (not --max-cycles, which was not given)."""
    from bayesmachine.modeldef import MAX_WATCHDOG, MAX_WATCHDOG_RUNS

    register_model(ModelDef(name="long-watch", description="a long watchdog", columns=FEATURES,
                            watchdog_runs=MAX_WATCHDOG_RUNS))
    try:
        model = ModelParams(name="long-watch", dmax=4)
        assert disparity_machine(model).max_cycles == MAX_WATCHDOG_RUNS * 17 <= MAX_WATCHDOG
        assert disparity_machine(model, counter_max=17, max_cycles=1000).max_cycles == 1000
        assert main(["run", "--model", "long-watch", "--dmax", "4", "--counter-max", "17", "-o", "x"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"bayesmachine run: error: --counter-max: counter_max 17: the long-watch model's "
                       f"watchdog, {MAX_WATCHDOG_RUNS} runs of counter max + 1 cycles, is "
                       f"{MAX_WATCHDOG_RUNS * 18} cycles, more than a machine counts ({MAX_WATCHDOG}): "
                       "give a smaller counter_max or a max_cycles"]
    finally:
        del MODELS["long-watch"]


def _lr(name: str, model: str) -> ModelDef:
    return ModelDef(name=name, description="a model with a right pass",
                    columns=(*FEATURES, consistency("right")),
                    passes=(PassDef(name="right", model=model, reference="right", machine_index=1),))


@pytest.mark.parametrize(("definition", "message"), [
    (ModelDef(name="census", description="taken", columns=FEATURES),
     "model 'census': the name is taken \\(models: paper, census, census-lr"),
    (_lr("bad-lr", "nope"), "model 'bad-lr': pass 'right' names an unknown model 'nope'"),
    (_lr("bad-lr", "bad-lr"), "model 'bad-lr': a cycle of passes: its pass 'right' runs the model itself"),
    (_lr("bad-lr", "census-lr"), "model 'bad-lr': pass 'right' runs model 'census-lr', which runs passes of "
     "its own: passes do not nest"),
    (ModelDef(name="bad-p0", description="another p0", columns=(Census, _OtherP0)),
     "model 'bad-p0': its option p0 is declared apart from the option of that name of model paper"),
    (ModelDef(name="bad-sigma", description="a census sigma of 0", columns=(Mean, Census),
              defaults={"census_sigma": 0.0}),
     "model 'bad-sigma': its defaults give no model: census_sigma must be a finite number > 0"),
])
def test_registering_a_bad_model_is_one_error(definition: ModelDef, message: str) -> None:
    before = dict(MODELS)
    with pytest.raises(ValueError, match=f"^{message}"):
        register_model(definition)
    assert MODELS == before


def test_register_takes_a_definition() -> None:
    with pytest.raises(TypeError, match="^register_model takes a ModelDef, not dict"):
        register_model({"name": "x"})  # type: ignore[arg-type]


# --- Two passes, two fed columns: each column reads its own pass's results, kept by pass name ---

_Consistency2 = consistency("right2", name="lr2")  # the consistency column fed by the pass "right2"


@pytest.fixture(scope="module")
def two_passes():
    definition = ModelDef(
        name="census-lr2", description="census-lr with a second right pass and its own consistency column",
        columns=(LeftPrior, AbovePrior, Mean, GradH, GradV, Census, consistency("right"), _Consistency2),
        passes=(PassDef(name="right", model="census", reference="right", machine_index=1),
                PassDef(name="right2", model="paper", reference="right", machine_index=2)))
    register_model(definition)
    try:
        yield ModelParams(name="census-lr2", dmax=8)
    finally:
        MODELS.pop("census-lr2")


def test_two_fed_columns_read_two_passes(two_passes: ModelParams, crop) -> None:
    model = two_passes
    machine = disparity_machine(model)
    w = machine.word_bits
    left, right, gt = crop
    fl, fr = model_planes(left, model), model_planes(right, model)
    region = OutputRegion.of_features(fl.shape, model.dmax)
    maps = declared_maps(model, fl, fr, w)
    assert list(maps) == ["right", "right2"] and not np.array_equal(maps["right"], maps["right2"])
    words = memory_words(fl, fr, model, machine, rows=slice(5, 6), above=np.full(region.shape[1], -1),
                         results={name: m[5:6] for name, m in maps.items()})
    fed = ((model.column(consistency("right")), "right"), (model.column(_Consistency2), "right2"))
    for k, (c, name) in enumerate(fed):
        first = pass_grid(model.pass_named(name), region).first
        np.testing.assert_array_equal(words[:, :, 5 + k], c.loaded(c.table(w), maps[name][5], first,
                                                                   region.map_columns))
    run = run_machine(prepare(left, right, model, gt), machine, "model", progress=False)
    assert list(run.passes) == ["right", "right2"]
    seeds = {name: r.machine.seed for name, r in run.passes.items()}
    assert len({machine.seed, *seeds.values()}) == 3  # each pass on a machine of its own
    assert run.passes["right2"].machine.columns == 3 and run.passes["right"].machine.columns == 1  # fused
