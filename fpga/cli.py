"""``bayesmachine synth``: the options; the flow itself is :func:`bayesmachine.fpga.synth.synth`.

The machine (``--top machine``) or the camera-fed StereoMachine (``--top stereo``: front end + FIFO +
machine) through Yosys and nextpnr, with a report of what it costs and how fast it runs (see
docs/fpga.md)."""

from __future__ import annotations

import argparse
import functools
from pathlib import Path

from bayesmachine.classify import DEFAULT_BINS, MAX_BINS
from bayesmachine.cliargs import (
    add_census_options,
    add_dmax_option,
    add_machine_options,
    float_in_range,
    int_in_range,
    machine_params_from_args,
    model_params_from_args,
    output_path,
)

from .classifier_synth import THROUGHPUT_DECISIONS, ClassifierTask
from .flow import ROUTERS
from .synth import Measure
from .targets import TARGETS

__all__ = ["register"]

MAX_PARALLEL = 256  # --machines with --top machine: bayesmachine.hdl.machines.ParallelMachines' bound
MAX_FREQ_MHZ = 1000.0  # --freq: no FPGA here comes near a 1 GHz clock


def register(subparsers: argparse._SubParsersAction, *, measure: Measure, classifier: ClassifierTask) -> None:
    """Add the ``synth`` and ``board`` subcommands; ``measure`` is the throughput measurement synth
    reports (:func:`bayesmachine.host.throughput.measure_cycles`), ``classifier`` what ``--top
    classifier`` fits and measures (``host.classification``'s)."""
    p = subparsers.add_parser(
        "synth",
        help="synthesize, place and route the machine for an FPGA (Yosys + nextpnr) and report",
        description="Put the machine (or several, --machines), or with --top stereo the camera-fed "
        "StereoMachine (front end + FIFO + machine, pixel pairs in), or with --top classifier the classifier "
        "top (likelihood memories addressed by the observation, a data set's size), behind the pin-saving "
        "wrapper, run "
        "Yosys and nextpnr (PyPI WebAssembly wheels: pip install 'bayesmachine[fpga]'), and write "
        "OUT/report.json and OUT/report.md: resources (block RAM included), fmax, critical path, machines "
        "that fit and the throughput measured on the bundled pair (with --top stereo: this design under "
        "Verilator on a frame of its width and 480 lines cut from the pair, every result checked against "
        "the model's; frames/s = fmax / the frame's wall cycles; with --top classifier decisions/s = fmax / "
        f"the wall cycles per decision of {THROUGHPUT_DECISIONS} held-out decisions of the data set under "
        "pysim, every one the model's). The first call of each tool compiles "
        "it (about a minute); nextpnr takes minutes on a full machine.",
    )
    devices = "; ".join(f"{t.name}: {t.device}" + (f" (fmax provisional: {t.fmax_provisional})"
                                                   if t.fmax_provisional else "") for t in TARGETS.values())
    p.add_argument("--target", required=True, choices=sorted(TARGETS), help=f"FPGA device ({devices})")
    p.add_argument("--top", choices=("machine", "stereo", "classifier"), default="machine",
                   help="machine: the machine alone, likelihood words in (default); stereo: the "
                   "StereoMachine, rectified pixel pairs in, the front end and its FIFO on chip "
                   "(docs/frontend.md); takes --width, --fifo-pixels and the model options; classifier: "
                   "the classifier top of a data set's size (docs/classifier.md); takes --dataset, --bins")
    c = p.add_argument_group("classifier (--top classifier; docs/classifier.md)")
    c.add_argument("--dataset", choices=classifier.datasets, default=None,
                   help="the data set whose size (classes, features, the most bins of a feature) the top "
                   "has and whose held-out fold (fold 0 of a stratified 5-fold split, split seed 0) "
                   "measures its decisions per second (default digits)")
    c.add_argument("--bins", type=int_in_range(1, MAX_BINS), default=None, metavar="B",
                   help=f"bins per feature, 1 .. {MAX_BINS} (default {DEFAULT_BINS})")
    g = p.add_argument_group("machine (the options of emit; --rng: an on-chip source)")
    add_dmax_option(g)
    add_machine_options(g, title=None)
    from bayesmachine.hdl.frontend.cli import add_options as add_stereo_options

    add_stereo_options(p)
    # --model (default DEFAULT_MODEL, cliargs.default_model): the model's machine, its throughput measured on
    # the model's words.
    add_census_options(p, title="model (the model's machine; with --top stereo its front end too)")
    p.add_argument("--machines", type=int_in_range(1, MAX_PARALLEL), default=1,
                   help="machines side by side (default 1): --top machine, behind one load and one result "
                   "stream; --top stereo, behind the one feature pipeline, map rows dealt to them, each "
                   f"with its own word generator (1 .. {MAX_PARALLEL} with --top machine, 1 .. 16 with --top "
                   "stereo; docs/frontend.md)")
    p.add_argument("--pin-width", type=int_in_range(1, 64), default=8,
                   help="wrapper chunk width in pins, 1 .. 64 (default 8)")
    # The place-and-route options stay None unless given: --synth-only refuses them (they would do nothing).
    p.add_argument("--freq", type=float_in_range(1, MAX_FREQ_MHZ), default=None,
                   help=f"nextpnr clock target in MHz, 1 .. {MAX_FREQ_MHZ:g} (default 150)")
    p.add_argument("--pnr-seed", type=int_in_range(0, 2**31 - 1), default=None,
                   help="nextpnr placement seed, 0 to 2^31 - 1 (default 1)")
    p.add_argument("--router", choices=ROUTERS, default=None,
                   help="nextpnr router (default router2: much faster than router1 on a full machine)")
    p.add_argument("--synth-only", action="store_true",
                   help="stop after Yosys: resources only, no fmax (for designs too big to route here)")
    p.add_argument("--no-throughput", action="store_true",
                   help="skip the throughput measurement (the model on the bundled pair; with --top stereo "
                   "also the design's frame under Verilator): no pixels/s or frames/s in the report")
    p.add_argument("-o", "--output", type=output_path, default=None,
                   help="output directory (default build/synth-TARGET, build/synth-stereo-TARGET with "
                   "--top stereo)")
    p.set_defaults(func=functools.partial(_run, measure=measure, classifier=classifier))

    from .boards.cli import register as register_board

    register_board(subparsers)


def _run(args: argparse.Namespace, *, measure: Measure, classifier: ClassifierTask) -> int:
    from bayesmachine.hdl.frontend.cli import check_top

    from .synth import synth

    check_top(args)  # stereo options with --top machine would do nothing: refused
    pnr = [flag for flag, value in (("--freq", args.freq), ("--pnr-seed", args.pnr_seed),
                                    ("--router", args.router)) if value is not None]
    if args.synth_only and pnr:
        raise ValueError(f"{', '.join(pnr)}: options of place and route, which --synth-only skips")
    given = [flag for flag, value in (("--dataset", args.dataset), ("--bins", args.bins))
             if value is not None]
    if args.top == "classifier":
        return _run_classifier(args, classifier)
    if given:
        raise ValueError(f"{', '.join(given)}: only with --top classifier (got --top {args.top})")
    model = model_params_from_args(args)
    params = machine_params_from_args(args, args.dmax, model=model)
    stereo: dict[str, object] = {"model": model}
    if args.top == "stereo":
        from bayesmachine.hdl.frontend.cli import fifo_pixels, stereo_params, width

        params = stereo_params(args, params)
        stereo = {"width": width(args), "model": model, "fifo_pixels": fifo_pixels(args)}
    name = f"synth-stereo-{args.target}" if args.top == "stereo" else f"synth-{args.target}"
    out = Path(args.output or f"build/{name}")
    synth(params, args.target, out, machines=args.machines, pin_width=args.pin_width,
          freq_mhz=150.0 if args.freq is None else args.freq,
          pnr_seed=1 if args.pnr_seed is None else args.pnr_seed, place=not args.synth_only,
          measure=None if args.no_throughput else measure, router=args.router or "router2",
          **stereo)  # type: ignore[arg-type]
    return 0


def _run_classifier(args: argparse.Namespace, task: ClassifierTask) -> int:
    """``--top classifier``: the top of the data set's size, its machine of the machine options."""
    from bayesmachine.cliargs import DEFAULT_DMAX
    from bayesmachine.hdl.classifier_cli import machine_options

    from .classifier_synth import synth_classifier

    other = [flag for flag, given in (("--dmax", args.dmax != DEFAULT_DMAX),
                                      ("--model", args.model is not None),
                                      ("--machines", args.machines != 1)) if given]
    if other:
        raise ValueError(f"{', '.join(other)}: not with --top classifier (its rows are the data set's "
                         "classes, one machine)")
    machine = machine_options(args)
    held = task.held_out(args.dataset or "digits", bins=DEFAULT_BINS if args.bins is None else args.bins,
                         machine=machine, decisions=THROUGHPUT_DECISIONS)
    out = Path(args.output or f"build/synth-classifier-{args.target}")
    synth_classifier(held.machine.params, held.machine.tables.features, held.bins, args.target, out,
                     pin_width=args.pin_width, freq_mhz=150.0 if args.freq is None else args.freq,
                     pnr_seed=1 if args.pnr_seed is None else args.pnr_seed, place=not args.synth_only,
                     router=args.router or "router2",
                     measure=None if args.no_throughput else (lambda: task.top_cycles(held)))
    return 0
