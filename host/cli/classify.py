"""``bayesmachine classify``: the machine as a naive-Bayes classifier on a data set (a CSV file or one of
scikit-learn's bundled ones), over a seeded k-fold or train/test split, beside the exact naive Bayes
on the same bins, ``CategoricalNB`` and ``GaussianNB``; OUT/report.json and OUT/reliability.png."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from bayesmachine.argtypes import (
    argument_type,
    float_in_range,
    input_path,
    int_arg,
    int_in_range,
    output_path,
    positive_float_at_most,
)
from bayesmachine.classify import DEFAULT_ALPHA, DEFAULT_BINS, MAX_BINS
from bayesmachine.cliargs import add_machine_options, refuse_unread_options, with_flag
from bayesmachine.errors import ParameterError
from bayesmachine.extras import needs_host, require
from bayesmachine.integrators import integrator_kind
from bayesmachine.outputs import OutputDir
from bayesmachine.sim.engines import ENGINES

from ..classification import BUNDLED_DATASETS

__all__ = ["register", "CLASSIFY_OUTPUTS"]

CLASSIFY_OUTPUTS = ("report.json", "reliability.png")
# The machine options the classifier takes (the layout's fields, columns, prior, normalize, ... are its own).
_MACHINE = ("integrator", "word_bits", "counter_max", "rng", "seed", "max_cycles")
_SKIPPED = ("columns", "lfsr_bits", "timeout_answer", "samples_per_clock", "normalize", "tie_break", "prior",
            "smtj_dwell", "smtj_spread", "smtj_share", "words_per_beat")
MAX_FOLDS = 100
MAX_ALPHA = 1e6  # the option's bound: with a million pseudo-counts per bin, counts barely move a table


def _fuse(text: str) -> int | None:
    if text == "none":
        return None
    value = int_arg(text)
    if value < 1:
        raise ValueError(f"expected none or a number of fused columns >= 1, got {text!r}")
    return value


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``classify`` to the ``bayesmachine`` parser."""
    p = subparsers.add_parser(
        "classify", help="the machine as a naive-Bayes classifier on a data set, beside exact naive Bayes",
        description="Bin a data set's features (quantile bins), count naive-Bayes tables and run every "
        "held-out sample as one decision of the machine (rows = classes); compare with the exact naive "
        "Bayes on the same bins, scikit-learn's CategoricalNB (same bins, same alpha) and GaussianNB. "
        "Writes OUT/report.json (accuracy per fold and mean, cycles per decision, the confidence's ECE and "
        "reliability table) and OUT/reliability.png; report.json last, so its presence means the run is "
        "complete (docs/classifier.md).")
    p.add_argument("data", type=input_path, metavar="DATA",
                   help=f"a CSV file with a header row (--label names its class column; every other column "
                   f"a number), or a bundled data set: {', '.join(BUNDLED_DATASETS)}")
    p.add_argument("--label", default=None, metavar="COLUMN", help="the CSV file's column of classes")
    s = p.add_argument_group("split")
    s.add_argument("--folds", type=int_in_range(2, MAX_FOLDS), default=None, metavar="K",
                   help="stratified shuffled K-fold (default 5)")
    s.add_argument("--test-size", type=float_in_range(0.0, 1.0), default=None, metavar="F",
                   help="one stratified train/test split, the fraction F (0 < F < 1) held out (instead of "
                   "--folds)")
    s.add_argument("--split-seed", type=int_in_range(0, 2**32 - 1), default=0, metavar="S",
                   help="the split's seed (default %(default)s)")
    c = p.add_argument_group("classifier")
    c.add_argument("--bins", type=int_in_range(1, MAX_BINS), default=DEFAULT_BINS, metavar="B",
                   help=f"the most quantile bins per feature (1 .. {MAX_BINS}, default %(default)s)")
    c.add_argument("--alpha", type=positive_float_at_most(MAX_ALPHA), default=DEFAULT_ALPHA, metavar="A",
                   help=f"additive smoothing of the tables, 0 < A <= {MAX_ALPHA:g}: CategoricalNB's rule "
                   "(default %(default)s)")
    c.add_argument("--fuse", type=argument_type(_fuse, "fuse"), default=1, metavar="K|none",
                   help="fuse the features into K energy-domain operator columns (default 1), or none: one "
                   "operator column per feature and a loaded prior column (at most 63 features; more than "
                   "15 need an --rng other than sobol)")
    c.add_argument("--engine", choices=ENGINES, default="model",
                   help="the engine that runs the decisions, bit for bit alike (default model; pysim is "
                   "slow)")
    add_machine_options(p, skip=_SKIPPED)
    p.add_argument("--quiet", action="store_true", help="no summary")
    p.add_argument("-o", "--output", required=True, type=output_path, metavar="OUT/",
                   help="output directory; only files bayesmachine wrote there are ever replaced or removed")
    p.set_defaults(func=needs_host(_cmd_classify))


def _options(args: argparse.Namespace) -> dict[str, Any]:
    given = {f: getattr(args, f) for f in _MACHINE if getattr(args, f) is not None}
    refuse_unread_options(args, given, [integrator_kind(given["integrator"])])
    return {"bins": args.bins, "alpha": args.alpha, "fuse": args.fuse, "engine": args.engine, **given}


def _cmd_classify(args: argparse.Namespace) -> int:
    require("sklearn", "scikit-learn")
    from ..classification import load_dataset, save_reliability_figure, split_folds, study
    from ..metrics import json_safe

    if args.folds is not None and args.test_size is not None:
        raise ValueError("--folds and --test-size: give one split, not both")
    options = _options(args)
    data = load_dataset(args.data, args.label)
    folds = 5 if args.folds is None and args.test_size is None else args.folds
    splits = split_folds(data.y, folds, args.test_size, args.split_seed)
    try:
        report = study(data, splits, options)
    except ParameterError as exc:
        raise with_flag(_flagged(exc)) from None
    report["split"] = ({"kind": "train-test", "test_size": args.test_size, "seed": args.split_seed}
                       if args.test_size is not None else {"kind": "k-fold", "folds": folds,
                                                           "seed": args.split_seed})
    with OutputDir(args.output, CLASSIFY_OUTPUTS, last="report.json") as out:
        out.write("reliability.png", lambda path: save_reliability_figure(path, report))
        out.write("report.json", lambda path: Path(path).write_text(
            json.dumps(json_safe(report), indent=2, allow_nan=False) + "\n"))
        written = out.commit()
    if not args.quiet:
        print(summary(report))
        print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _flagged(exc: ParameterError) -> ParameterError:
    """The classifier's own parameters said with their flags (the machine's: ``with_flag``)."""
    own = {"fuse": "--fuse", "bins": "--bins", "alpha": "--alpha"}
    if exc.parameter in own and not str(exc).startswith("--"):
        return ParameterError(f"{own[exc.parameter]}: {exc}", exc.parameter)
    return exc


def summary(r: dict[str, Any]) -> str:
    """The report in a few lines."""
    a = r["accuracy"]
    m = r["machine"]
    split = r["split"]
    how = f"{split['folds']}-fold" if split["kind"] == "k-fold" else f"test size {split['test_size']}"
    machine = " ".join([m["integrator"], *integrator_kind(m["integrator"]).label_parts(m)])
    cycles, conf = r["cycles_per_decision"], r["confidence"]
    return (f"{r['data']}: {r['samples']} samples, {r['features']} features, {r['classes']} classes, {how}; "
            f"{machine}, {r['operator_columns']} operator columns\n"
            f"  accuracy: machine {a['machine']:.4f}, exact NB (same bins) {a['exact_nb']:.4f} "
            f"({r['machine_minus_exact_points']:+.2f} points), CategoricalNB {a['categorical_nb']:.4f}, "
            f"GaussianNB {a['gaussian_nb']:.4f}\n"
            f"  cycles per decision {cycles['mean']:.2f} (max {cycles['max']}), confidence ECE "
            f"{conf['machine']['ece']:.4f} (exact NB {conf['exact_nb']['ece']:.4f})")
