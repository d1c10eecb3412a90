"""The on-chip front end against the host and against itself, over the golden snapshot's configurations.

For every configuration of ``benchmarks/golden_snapshot.py`` (its ``CONFIGS``: the three models and
their option sets on crops of the bundled pair; and its ``RTL_CONFIGS``' models on crop "a" cut to
their width), on the front end's machine (``stereo_machine_params``: the same machine with the front
end's words per beat, which change no result):

- **words**: the ``FrontEnd``'s words under pysim, every pass's, equal the host's (``pass_words``),
  each column fed as the run feeds it (an ABOVE column from stand-in MAPs of the row above, a PASS
  column from stand-in MAPs of the pass it reads; random, seeded);
- **results**: the ``StereoMachine`` under Verilator (``run_machine(..., feed="pixels")``) equals the
  model engine on the host's words (``feed="words"``), every array, the declared passes' too; and its
  wall cycles.

``save DIR`` writes ``frontend.json`` (per configuration: the words' and the results' SHA-256, the
wall cycles); ``check DIR`` recomputes it with the code installed now and names every difference, so a
restructured RTL whose RTLIL hash moved proves it computes the same words and results, in the same
clock cycles. Either action fails (exit 1) if the front end disagrees with the host or the model.

Run: python benchmarks/frontend_equivalence.py save /work/golden/frontend   (on the code to keep)
     python benchmarks/frontend_equivalence.py check /work/golden/frontend  (after the change)
     (``--per-column``: the models with a fused column without it, as golden_snapshot.py's)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from golden_snapshot import CONFIGS, CROPS, RTL_CONFIGS, _pair, model_of

from bayesmachine.cli import Parser, run_script
from bayesmachine.hdl.frontend.stereo import FrontEnd, stereo_machine_params
from bayesmachine.host.features import model_planes
from bayesmachine.host.likelihoods import pass_grid, pass_words
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams, pass_machine
from bayesmachine.outputs import atomic_write_text
from bayesmachine.region import OutputRegion
from bayesmachine.sim.stereo_testbench import run_frontend_passes

ARRAYS = ("map", "counts", "cycles", "nomatch", "timeout")


def configurations() -> dict[str, tuple[tuple[np.ndarray, np.ndarray], dict[str, Any], dict[str, Any]]]:
    """name -> (pair, model keywords, machine keywords)."""
    out = {name: (_pair(crop), model_kw, machine_kw)
           for name, (crop, model_kw, machine_kw) in CONFIGS.items()}
    for name, (model_kw, width) in RTL_CONFIGS.items():
        left, right = _pair("a")
        out[name] = ((left[:, :width], right[:, :width]), model_kw, {})
    assert set(CROPS) >= {"a"}
    return out


def _sha(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _stand_in(rng: np.random.Generator, rows: int, width: int, dmax: int) -> np.ndarray:
    return rng.integers(-1, dmax + 1, (rows, width))


def _host_words(model: ModelParams, params: Any, pair: tuple[np.ndarray, np.ndarray],
                maps: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every pass's words, row by row, each column fed from the stand-in MAPs ``maps`` (by pass name)."""
    feats = tuple(model_planes(image, model) for image in pair)
    region = OutputRegion.of_features(feats[0].shape, model.dmax, model.margin)
    out: dict[str, np.ndarray] = {}
    for p in model.passes:
        machine = params if p.model is model else pass_machine(model, params, p.name)
        rows = []
        for y in range(region.shape[0]):
            above = np.full(maps[p.name].shape[1], -1) if y == 0 else maps[p.name][y - 1]
            results = {name: m[y : y + 1] for name, m in maps.items() if name != p.name}
            rows.append(pass_words(p, *feats, machine, rows=slice(y, y + 1), above=above, results=results))
        out[p.name] = np.concatenate(rows)
    return out


def _frontend_words(model: ModelParams, params: Any, pair: tuple[np.ndarray, np.ndarray],
                    maps: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every pass's words from the ``FrontEnd`` under pysim, by pass name, each pass whose MAPs it reads
    fed the stand-ins ``maps``."""
    front = FrontEnd(params=params, model=model, width=pair[0].shape[1])
    got = run_frontend_passes(front, [pair], maps, in_stall=0.2, out_stall=0.2, result_delay=4, seed=1)
    return {name: words for name, (words, _) in got.items()}


def compute(name: str, pair: tuple[np.ndarray, np.ndarray], model_kw: dict[str, Any],
            machine_kw: dict[str, Any], per_column: bool = False) -> tuple[dict[str, Any], list[str]]:
    model = model_of(model_kw, per_column)
    params = stereo_machine_params(model.dmax, model=model, **machine_kw)
    region = OutputRegion.of_model(pair[0].shape, model)
    rng = np.random.default_rng(7)
    maps = {p.name: _stand_in(rng, region.shape[0], pass_grid(p, region).width, model.dmax)
            for p in model.passes}
    bad: list[str] = []
    want = _host_words(model, params, pair, maps)
    got = _frontend_words(model, params, pair, maps)
    for p in want:
        if got[p].shape != want[p].shape or not np.array_equal(got[p], want[p]):
            bad.append(f"{name}: the front end's {p} pass words differ from the host's")
    prepared = prepare(*pair, model, reference=False)
    runs = {feed: run_machine(prepared, params, engine, progress=False, feed=feed)
            for feed, engine in (("words", "model"), ("pixels", "verilator"))}
    arrays = {}
    for field in ARRAYS:
        a, b = getattr(runs["words"], field), getattr(runs["pixels"], field)
        arrays[field] = b
        if not np.array_equal(a, b):
            bad.append(f"{name}: --feed pixels {field} differs from the model's")
    for pass_name, record in runs["pixels"].passes.items():
        for field in ("map", "cycles", "timeout"):
            a, b = getattr(runs["words"].passes[pass_name], field), getattr(record, field)
            arrays[f"{pass_name}_{field}"] = b
            if not np.array_equal(a, b):
                bad.append(f"{name}: --feed pixels {pass_name} {field} differs from the model's")
    figures = {"words_sha256": _sha(*(got[p] for p in sorted(got))),
               "results_sha256": _sha(*(arrays[k] for k in sorted(arrays))),
               "wall_cycles": int(runs["pixels"].wall_cycles),
               "output_pixels": int(region.pixels),
               "machine": json.loads(json.dumps(params.to_dict()))}
    return figures, bad


def main(argv: list[str] | None = None) -> int:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("action", choices=("save", "check"))
    ap.add_argument("folder", type=Path)
    ap.add_argument("--only", nargs="*", default=None, help="configurations (default all)")
    ap.add_argument("--per-column", action="store_true",
                    help="models with a fused column without it (golden_snapshot.py --per-column)")
    args = ap.parse_args(argv)
    configs = configurations()
    names = args.only or list(configs)
    unknown = [n for n in names if n not in configs]
    if unknown:
        raise ValueError(f"--only: no configuration {', '.join(unknown)} (they are {', '.join(configs)})")
    path = args.folder / "frontend.json"
    saved = json.loads(path.read_text()) if path.exists() else {}
    problems: list[str] = []
    for name in names:
        t0 = time.perf_counter()
        figures, bad = compute(name, *configs[name], per_column=args.per_column)
        problems += bad
        if args.action == "save":
            saved[name] = figures
            status = "saved"
        else:
            was = saved.get(name)
            moved = [k for k in figures if was is None or was.get(k) != figures[k]]
            problems += [f"{name}: {k}: {figures[k]} != saved {None if was is None else was.get(k)}"
                         for k in moved]
            status = "DIFFERS" if moved else "equal"
        status = "WRONG" if bad else status
        print(f"{name:24s} {status} (wall cycles {figures['wall_cycles']}, "
              f"{time.perf_counter() - t0:.0f} s)", flush=True)
    if args.action == "save":
        args.folder.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, json.dumps(saved, indent=1, sort_keys=True) + "\n")
    for p in problems:
        print(p, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
