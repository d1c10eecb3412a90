"""Benchmark: resources and fmax of the census machine on the ECP5-85F against B, samples per clock.

For each B of ``--samples`` (default 1, 4, 8), one ``bayesmachine synth --top machine --model MODEL
--target TARGET --samples-per-clock B -o OUT-B<B>`` as a subprocess (one at a time; options this
script does not know, e.g. ``--synth-only`` or a model option, are passed through to every run), then
per B one table row: LUT4, CCU2C, LUT4 sites (a CCU2C takes two), FF, DP16KD, MULT18X18D, fmax, the
critical path, and the compute cycles per pixel of that B on the bundled pair (model engine, the
model's default machine: ``bench_samples.measure``), its wall cycles per pixel (loading included,
``pixel_wall_cycles``) at the machine's load beat and with a pixel's words in one beat, and the pixels
per second = fmax / wall cycles. A design that does not place, or a run stopped at ``--time-limit``,
gets a row saying so, with its synthesis resources and the utilisation nextpnr printed; a failed
place and route is retried with the next of ``--pnr-seeds``. The figures also go to ``--json``
(default build/synth_samples.json; ``--keep`` keeps its rows of the B not run now, each row names
the commit it was measured on). Prints figures; asserts nothing.
Run: python benchmarks/bench_synth_samples.py [--samples 1,4,8] [--reuse] [--keep] [--time-limit MIN]
     [--pnr-seeds 1,2] [synth options]
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from bench_samples import measure

from bayesmachine.cli import Parser, build_parser, run_script
from bayesmachine.cliargs import (
    int_in_range,
    int_of,
    machine_params_from_args,
    model_params_from_args,
    output_path,
    positive_float_at_most,
    value_list,
)
from bayesmachine.fpga.flow import cell_counts
from bayesmachine.fpga.report import logic_cells, resources
from bayesmachine.fpga.targets import TARGETS, get_target
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import ModelParams
from bayesmachine.host.run import prepare
from bayesmachine.models import model_names
from bayesmachine.outputs import atomic_write_text
from bayesmachine.params import SAMPLES_PER_CLOCK

# nextpnr's "Device utilisation" lines: "Info:     TRELLIS_COMB: 90000/83640   107%".
UTILISATION = re.compile(r"^Info:\s+(\w+):\s+(\d+)/\s*(\d+)\s+(\d+)%", re.M)


def nextpnr_utilisation(log: str) -> dict[str, dict[str, int]]:
    """The last "Device utilisation" nextpnr printed in ``log``, by cell type (used ones only)."""
    util: dict[str, dict[str, int]] = {}
    for name, used, avail, _ in UTILISATION.findall(log):
        if int(used):
            util[name] = {"used": int(used), "available": int(avail)}
    return util


def run_synth(b: int, args: argparse.Namespace, extra: list[str]) -> dict:
    """The synth run at B = ``b`` (or its report, with ``--reuse``): what it measured, or why not. A
    place and route that fails is retried with the next of ``--pnr-seeds``; a stopped run is not."""
    out = Path(f"{args.out}-B{b}")
    log, report = Path(f"{out}.log"), out / "report.json"
    row: dict = {"samples_per_clock": b, "out": str(out), "failed_seeds": []}
    base = ["synth", "--top", "machine", "--model", args.model, "--target", args.target,
            "--samples-per-clock", str(b), "-o", str(out), *extra]
    if args.reuse and report.exists():  # the log's first line is the command that wrote the report
        command = " ".join(["bayesmachine", *base])
        row["command"] = log.read_text().splitlines()[0] if log.exists() else command
        return from_report(row, report)
    for seed in [None] if "--synth-only" in extra else args.pnr_seeds:
        argv = [*base, *([] if seed is None else ["--pnr-seed", str(seed)])]
        row["command"] = " ".join(["bayesmachine", *argv])
        print(f"B = {b}: {row['command']}", flush=True)
        t0 = time.monotonic()
        row["status"] = call([sys.executable, "-m", "bayesmachine", *argv], log, row["command"],
                             args.time_limit)
        row["seconds"] = round(time.monotonic() - t0, 1)
        if row["status"] is None:
            return from_report(row, report)
        if row["status"].startswith("stopped"):
            break
        row["status"] += f": {last_error(log, out)}"
        row["failed_seeds"].append({"seed": seed, "status": row["status"]})
    return failed(row, out, get_target(args.target))


def call(cmd: list[str], log: Path, command: str, time_limit: float | None) -> str | None:
    """Run ``cmd`` (its output in ``log``, after the ``command`` line): None, or why it has no report."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as f:
        f.write(command + "\n")
        f.flush()
        with subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT) as proc:
            try:
                rc = proc.wait(timeout=time_limit * 60 if time_limit else None)
            except subprocess.TimeoutExpired:
                proc.send_signal(signal.SIGTERM)  # synth ends its tool's process group with it
                proc.wait()
                return f"stopped after {time_limit:g} min"
    return None if rc == 0 else f"synth failed (exit {rc})"


def from_report(row: dict, report: Path) -> dict:
    """The row's figures from synth's ``report.json``."""
    rep = json.loads(report.read_text())
    row.update({k: rep.get(k) for k in ("machine", "resources", "utilization", "fmax_mhz", "critical_path",
                                        "pnr_utilization", "throughput", "measured")})
    row["status"] = "placed and routed" if rep.get("fmax_mhz") else "synthesis only"
    row.setdefault("seconds", rep.get("seconds"))
    return row


def last_error(log: Path, out: Path) -> str:
    """The tool's ERROR line (nextpnr's log, else synth's own output), or its last line."""
    for path in (out / "nextpnr.log", log):
        lines = path.read_text(errors="replace").splitlines() if path.exists() else []
        errors = [ln for ln in lines if "ERROR" in ln or "error:" in ln]
        if errors:
            return errors[-1].strip()
    lines = log.read_text(errors="replace").strip().splitlines()
    return lines[-1] if lines else "no output"


def failed(row: dict, out: Path, target) -> dict:  # noqa: ANN001
    """A run without a report: its synthesis resources (if Yosys finished) and nextpnr's utilisation."""
    stat = out / "stat.json"
    if stat.exists() and (out / "synth.key").exists():
        row["resources"] = resources(target, cell_counts(json.loads(stat.read_text())))
    log = out / "nextpnr.log"
    if log.exists():
        row["pnr_utilization"] = nextpnr_utilisation(log.read_text(errors="replace"))
    return row


def add_cycles(row: dict, prep, model: ModelParams) -> None:  # noqa: ANN001
    """The compute and wall cycles per pixel of the model's default machine at this B, and the pixels
    per second at the row's fmax; whether the synthesized machine is that machine."""
    m = measure(prep, model, row["samples_per_clock"])
    row["cycles"] = {k: round(m[k], 3) for k in ("cycles_per_pixel", "wall_cycles_per_pixel",
                                                 "wall_cycles_per_pixel_one_beat")}
    row["cycles"]["timeouts"] = m["timeouts"]
    if row.get("machine") is not None:
        row["same_machine"] = row["machine"] == json.loads(json.dumps(m["machine"].to_dict()))
    fmax = row.get("fmax_mhz")
    if fmax:
        row["pixels_per_second"] = round(fmax * 1e6 / m["wall_cycles_per_pixel"], 1)
        row["pixels_per_second_one_beat"] = round(fmax * 1e6 / m["wall_cycles_per_pixel_one_beat"], 1)


def table(rows: list[dict], target_name: str) -> str:
    """The rows as a Markdown table, then each row's critical path or why it has none."""
    target = get_target(target_name)
    lines = ["| B | LUT4 | CCU2C | LUT4 sites | FF | DP16KD | MULT18X18D | fmax (MHz) | compute cycles/px "
             "| wall cycles/px (1 beat) | Mpx/s (1 beat) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    notes = []
    for r in rows:
        res, c = r.get("resources"), r["cycles"]
        cells = ["—"] * 6
        if res:
            sites = logic_cells(target, res)
            cells = [f"{res['lut4']:,}", f"{res['carry']:,}", f"{sites:,} ({sites / target.luts:.0%})",
                     f"{res['ff']:,} ({res['ff'] / target.ffs:.0%})", f"{res['bram']}", f"{res['dsp']}"]
        fmax = f"{r['fmax_mhz']:.1f}" if r.get("fmax_mhz") else "—"
        rate = (f"{r['pixels_per_second'] / 1e6:.2f} ({r['pixels_per_second_one_beat'] / 1e6:.2f})"
                if r.get("pixels_per_second") else "—")
        walls = f"{c['wall_cycles_per_pixel']:.2f} ({c['wall_cycles_per_pixel_one_beat']:.2f})"
        lines.append(f"| {r['samples_per_clock']} | {' | '.join(cells)} | {fmax} "
                     f"| {c['cycles_per_pixel']:.2f} | {walls} | {rate} |")
        notes.append(f"B = {r['samples_per_clock']}: {describe(r)}")
    return "\n".join(lines + [""] + notes)


def describe(row: dict) -> str:
    """The row's critical path, or its status and nextpnr's utilisation."""
    cp = row.get("critical_path") or {}
    text = row["status"]
    if cp:
        text = (f"critical path {cp['start']} (net {cp['start_net']}) -> {cp['end']} (net {cp['end_net']}): "
                f"{cp['delay_ns']:.2f} ns ({cp['routing_ns']:.2f} routing, {cp['levels']} logic steps)")
    elif row.get("pnr_utilization"):
        text += "; nextpnr: " + ", ".join(f"{k} {v['used']:,}/{v['available']:,}"
                                          for k, v in row["pnr_utilization"].items())
    for f in row.get("failed_seeds", []):
        if f["status"] != row["status"]:
            text += f"; with --pnr-seed {f['seed']}: {f['status']}"
    if row.get("same_machine") is False:
        text += "; the synthesized machine is not the model's default machine the cycles are of"
    return text


def commit() -> str:
    """HEAD of this tree, marked when the tree has uncommitted changes."""
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                           text=True).stdout.strip()
    return head + (" (uncommitted changes)" if dirty else "")


def main(argv: list[str] | None = None) -> None:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0], allow_abbrev=False,
                epilog="Other options are passed to every bayesmachine synth run.")
    ap.add_argument("--samples", type=value_list(int_of(SAMPLES_PER_CLOCK), "B"), default="1,4,8",
                    help="the B to run, comma-separated (default 1,4,8)")
    ap.add_argument("--model", choices=model_names(), default="census")
    ap.add_argument("--target", choices=sorted(TARGETS), default="ecp5-85k")
    ap.add_argument("--out", type=output_path, default="build/synth",
                    help="output directory prefix: OUT-B<B> (default build/synth)")
    ap.add_argument("--json", type=output_path, default="build/synth_samples.json")
    ap.add_argument("--reuse", action="store_true",
                    help="take an existing OUT-B<B>/report.json instead of a run")
    ap.add_argument("--time-limit", type=positive_float_at_most(7 * 24 * 60), default=None,
                    help="stop a synth run after this many minutes (at most a week)")
    ap.add_argument("--pnr-seeds", type=value_list(int_in_range(0, 2**31 - 1), "seed"), default="1",
                    help="nextpnr seeds, comma-separated: a failed place and route is retried with the next "
                    "(default 1)")
    ap.add_argument("--keep", action="store_true",
                    help="keep the rows of --json's previous figures for the B not run now (same model, "
                    "target and options)")
    args, extra = ap.parse_known_args(argv)
    samples = args.samples
    # The options passed on to every synth run, checked as synth checks them, before any run.
    synth_args = build_parser().parse_args(["synth", "--target", args.target, "--model", args.model, *extra])
    model = model_params_from_args(synth_args)
    for b in samples:
        machine_params_from_args(synth_args, synth_args.dmax, model=model, samples_per_clock=b)
    tree = commit()
    rows = [run_synth(b, args, extra) for b in samples]
    model = ModelParams(name=args.model)
    left, right, gt = bundled_pair()
    prep = prepare(left, right, model, gt, reference=False)
    for row in rows:
        row["commit"] = tree
        add_cycles(row, prep, model)
    rows += kept(args, extra, samples) if args.keep else []
    rows.sort(key=lambda r: r["samples_per_clock"])
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    record = {"model": args.model, "target": args.target, "extra_options": extra, "rows": rows}
    atomic_write_text(args.json, json.dumps(record, indent=2) + "\n")
    print(f"\n{args.model} machine on {args.target}, trees {', '.join(sorted({r['commit'] for r in rows}))}; "
          f"figures in {args.json}\n")
    print(table(rows, args.target))


def kept(args: argparse.Namespace, extra: list[str], samples: list[int]) -> list[dict]:
    """The previous figures' rows (``--json``) of the B not in ``samples``, if they are of the same
    model, target and options."""
    path = Path(args.json)
    if not path.exists():
        return []
    old = json.loads(path.read_text())
    if (old.get("model"), old.get("target"), old.get("extra_options")) != (args.model, args.target, extra):
        raise ValueError(f"{path}: figures of other options ({old.get('model')}, {old.get('target')}, "
                         f"{old.get('extra_options')}): --keep would mix them")
    rows = [r for r in old["rows"] if r["samples_per_clock"] not in samples]
    for r in rows:
        r.setdefault("commit", old.get("commit"))
    return rows

if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
