"""K machines behind one front end: the table of docs/fpga.md from measured reports.

Each configuration is a place-and-route report and a Verilator run of the same design on a
640 x 480 pair (measured; nothing here is derived from one lane):

    bayesmachine synth --top stereo --width 640 --machines K --model census --target ecp5-85k \
        -o build/synth-stereo-kK
    bayesmachine run --engine verilator --feed pixels --machines K --model census --crop 50,10,640,480 \
        -o build/run-vga-kK

(--model census in both: the default model, census-sgm, runs on one machine a pass.)

    python benchmarks/bench_machines.py K:build/synth-stereo-kK:build/run-vga-kK ...

Prints, per K: LUT4, CCU2C, LUT4 sites (CCU2C = 2), FF, DP16KD (and their share of the device),
nextpnr's fmax, the frame's wall cycles (``report.json`` ``wall_cycles`` of the run: first pixel in
to last result out), wall cycles per output pixel, VGA fps = fmax / wall cycles per frame and the
input bandwidth at that rate (16 bits per pixel pair, every pixel of the frame). A synthesis
without place and route (``--synth-only``, or nextpnr failing) has no fmax: "—".
A run report's ``machines`` must match K, and its frame must be 640 x 480.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from bayesmachine.cli import Parser, run_script
from bayesmachine.cliargs import argument_type

PIXEL_BITS = 16  # a pixel pair of the stereo top's input stream


def _config(text: str) -> tuple[int, Path | None, Path | None]:
    """``K:SYNTH_DIR:RUN_DIR`` ('-': none), K machines 1 .. 16."""
    try:
        k_text, synth_dir, run_dir = text.split(":")
        k = int(k_text)
    except ValueError:
        raise ValueError(f"{text!r} is not K:SYNTH_DIR:RUN_DIR") from None
    if not 1 <= k <= 16:
        raise ValueError(f"{text!r}: K must be 1 .. 16 machines")
    return k, *(None if d == "-" else Path(d) for d in (synth_dir, run_dir))  # type: ignore[return-value]


def _load(path: Path) -> dict:
    report = path / "report.json"
    if not report.is_file():
        raise ValueError(f"no report.json in {path}")
    try:
        return json.loads(report.read_text())
    except ValueError as exc:
        raise ValueError(f"{report}: not JSON ({exc})") from None


def row(k: int, synth: dict | None, run: dict | None) -> dict[str, object]:
    """One configuration's figures (None where not measured)."""
    out: dict[str, object] = {"machines": k}
    if synth is not None:
        if synth.get("machines", synth.get("words_per_beat")) != k or synth.get("top") != "stereo":
            raise ValueError(f"the synth report is not --top stereo --machines {k}")
        res, util = synth["resources"], synth["utilization"]
        out |= {"lut4": res["lut4"], "ccu2c": res["carry"], "sites": res["lut4"] + 2 * res["carry"],
                "ff": res["ff"], "dp16kd": res["bram"], "util": util, "fmax": synth.get("fmax_mhz"),
                "device": synth["device"]}
    if run is not None:
        if run.get("machines", 1) != k or run.get("feed") != "pixels":
            raise ValueError(f"the run report is not --feed pixels --machines {k}")
        h, w = run["image_shape"]
        wall = run["wall_cycles"]
        out |= {"frame": f"{w}x{h}", "wall": wall, "pixels": run["pixels"],
                "wall_per_pixel": wall / run["pixels"], "input_pixels": w * h}
    if out.get("fmax") and out.get("wall"):
        fps = out["fmax"] * 1e6 / out["wall"]  # type: ignore[operator]
        out["fps"] = fps
        out["input_mbit_s"] = fps * out["input_pixels"] * PIXEL_BITS / 1e6  # type: ignore[operator]
    return out


def _f(value: object, fmt: str) -> str:
    return "—" if value is None else format(value, fmt)


def table(rows: list[dict[str, object]]) -> str:
    lines = ["| K | LUT4 | CCU2C | LUT4 sites | FF | DP16KD | fmax | frame | wall cycles / frame | "
             "wall / output pixel | VGA fps | input |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        util = r.get("util") or {}
        sites = "—" if "sites" not in r else f"{r['sites']:,} ({100 * util.get('lut4', 0):.0f} %)"
        ff = "—" if "ff" not in r else f"{r['ff']:,} ({100 * util.get('ff', 0):.0f} %)"
        bram = "—" if "dp16kd" not in r else f"{r['dp16kd']} ({100 * util.get('bram', 0):.0f} %)"
        fmax = "—" if r.get("fmax") is None else f"{r['fmax']:.1f} MHz"
        lines.append(
            f"| {r['machines']} | {_f(r.get('lut4'), ',')} | {_f(r.get('ccu2c'), ',')} | {sites} | {ff} | "
            f"{bram} | {fmax} | {r.get('frame', '—')} | {_f(r.get('wall'), ',')} | "
            f"{_f(r.get('wall_per_pixel'), '.2f')} | {_f(r.get('fps'), '.2f')} | "
            f"{'—' if r.get('input_mbit_s') is None else format(r['input_mbit_s'], '.1f') + ' Mbit/s'} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    ap.add_argument("configs", nargs="+", metavar="K:SYNTH_DIR:RUN_DIR",
                    type=argument_type(_config, "config"),
                    help="machines, the synth output directory and the run output directory ('-': none)")
    args = ap.parse_args(argv)
    rows = []
    for k, synth_dir, run_dir in args.configs:
        synth = None if synth_dir is None else _load(synth_dir)
        run = None if run_dir is None else _load(run_dir)
        try:
            rows.append(row(k, synth, run))
        except (KeyError, TypeError, ZeroDivisionError) as exc:  # a report of another kind or version
            raise ValueError(f"K {k}: {synth_dir} / {run_dir} do not hold the synth and run reports this "
                             f"reads (no {exc})") from None
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
