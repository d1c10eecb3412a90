"""Golden snapshot of the models' host computations, to prove a refactor changes no result.

``save DIR`` writes, for each configuration of :data:`CONFIGS` (the three models over small crops of
the bundled pair, Dmax 4..12, word bits 8 and 10, counter max 4 and 16, the census-lr options
varied, ``neighbour_prior=False``, ``prior="loaded"``, census window 5), one ``NAME.npz`` with:
the likelihood-memory words of every map row (``memory_words``, and of census-lr's right pass,
``pass_words``), the float64 and the quantized references' posteriors and MAPs (census-lr: the right
passes' MAPs too), ``run_machine``'s results on the model engine (counts, map, cycles, no match,
timeout, the right pass's map, cycles and timeout), and ``NAME.json`` with the model's ``to_dict()``,
the ``MachineParams.to_dict()`` of ``disparity_machine`` and of the right pass's ``pass_machine`` (whose
feedback tables are their ``feedback_words``/``feedback_nomatch_word``); and for the on-chip front end
(:data:`RTL_CONFIGS`) the SHA-256 of a small ``StereoMachine``'s RTLIL per model. ``check DIR`` recomputes
everything with the code installed now and compares it bit for bit (exit 1 naming every difference).
``--per-column`` builds every model that has the fused column (``fuse_columns``) without it: one
operator column per piece of evidence, the machine the snapshots before the fused column hold.

Run: python benchmarks/golden_snapshot.py save /work/golden/columns    (once, on the code to keep)
     python benchmarks/golden_snapshot.py check /work/golden/columns   (after each refactor step)
     python benchmarks/golden_snapshot.py check --per-column /work/golden/columns
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

from bayesmachine.cli import Parser, run_script
from bayesmachine.host.features import model_planes
from bayesmachine.host.images import bundled_pair
from bayesmachine.host.likelihoods import memory_words, pass_words
from bayesmachine.host.reference import declared_maps, reference_bands, reference_quantized
from bayesmachine.host.run import prepare, run_machine
from bayesmachine.models import ModelParams, disparity_machine, pass_machine
from bayesmachine.outputs import atomic_file, atomic_write_text
from bayesmachine.region import OutputRegion

# Crops (x, y, width, height, shift) of the bundled Motorcycle pair (500 x 741): the right image's crop
# starts ``shift`` pixels further left, so the crop's disparities (49.6, 29..42, 21.6) fall in 0..Dmax.
CROPS = {"a": (300, 200, 40, 16, 46), "b": (120, 330, 46, 13, 31), "c": (520, 60, 36, 18, 17)}

# name -> (crop, model keywords, machine keywords). Every model names itself (the default changes).
CONFIGS: dict[str, tuple[str, dict[str, Any], dict[str, Any]]] = {
    "paper-d4": ("a", {"name": "paper", "dmax": 4}, {}),
    "paper-d12-w8-c4": ("b", {"name": "paper", "dmax": 12}, {"word_bits": 8, "counter_max": 4}),
    "paper-sigmas-loaded": ("c", {"name": "paper", "dmax": 8, "p0": 0.05, "sigma_m": 7.0, "sigma_gh": 12.0,
                                  "sigma_gv": 9.0, "p_nm0": 0.03, "sigma_nm": 5.0},
                            {"prior": "loaded", "rng": "lfsr"}),
    "census-d6": ("a", {"name": "census", "dmax": 6}, {}),
    "census-w5-d8-w8-c4": ("a", {"name": "census", "dmax": 8, "census_window": 5},
                           {"word_bits": 8, "counter_max": 4}),
    "census-noprior": ("a", {"name": "census", "dmax": 6, "neighbour_prior": False}, {}),
    "census-noprior-loaded": ("c", {"name": "census", "dmax": 5, "neighbour_prior": False},
                              {"prior": "loaded", "rng": "lfsr-shared"}),
    "census-options": ("b", {"name": "census", "dmax": 10, "census_p0": 0.05, "census_sigma": 4.5,
                             "census_nomatch_h": 4, "prior_eps": 0.1, "prior_s": 3.0, "prior_nomatch": 0.3},
                       {"rng": "lfsr", "tie_break": "lowest-index", "max_cycles": 60}),
    "census-smtj": ("c", {"name": "census", "dmax": 4},
                    {"rng": "smtj", "smtj_dwell": 3.0, "smtj_spread": 0.05, "counter_max": 4}),
    "lr-d6": ("a", {"name": "census-lr", "dmax": 6}, {}),
    "lr-issue": ("b", {"name": "census-lr", "dmax": 10, "lr_right_nomatch": False, "lr_neutral": False,
                       "lr_nomatch": False}, {"word_bits": 8, "counter_max": 4}),
    "lr-options": ("c", {"name": "census-lr", "dmax": 12, "census_window": 5, "lr_beta": 0.3,
                         "lr_gamma": 0.05, "lr_tolerance": 0, "lr_right_max_cycles": 150,
                         "prior_nomatch": 0.2, "census_sigma": 4.0},
                   {"counter_max": 4, "rng": "lfsr"}),
    "lr-w8-c16": ("a", {"name": "census-lr", "dmax": 8, "lr_tolerance": 2},
                  {"word_bits": 8, "max_cycles": 500}),
}

# The on-chip front end's design (StereoMachine, RTLIL text, hashed): name -> (model keywords, width).
RTL_CONFIGS: dict[str, tuple[dict[str, Any], int]] = {
    "rtl-paper": ({"name": "paper", "dmax": 4}, 24),
    "rtl-census": ({"name": "census", "dmax": 4}, 24),
    "rtl-census-w5-noprior": ({"name": "census", "dmax": 4, "census_window": 5,
                               "neighbour_prior": False}, 24),
    "rtl-census-lr": ({"name": "census-lr", "dmax": 4}, 24),
}

BAND_ROWS = 5  # references band by band, each carrying the MAP row above into the next


# --- The API this script reads (the lines a refactor may have to follow; the data do not change) ---
RIGHT = "right"  # census-lr's declared pass


def has_prior(model: ModelParams, machine: Any) -> bool:
    return machine.prior == "neighbour"


def has_right_pass(model: ModelParams) -> bool:
    return model.name == "census-lr"


def right_machine(model: ModelParams, machine: Any) -> Any:
    return pass_machine(model, machine, RIGHT)


def right_words(model: ModelParams, rmachine: Any, feats: tuple, y: int, above: np.ndarray) -> np.ndarray:
    return pass_words(model.pass_named(RIGHT), *feats, rmachine, rows=slice(y, y + 1), above=above)


def own_words(model: ModelParams, machine: Any, feats: tuple, y: int, above: np.ndarray | None,
              right_row: np.ndarray | None) -> np.ndarray:
    results = None if right_row is None else {RIGHT: right_row[None]}
    return memory_words(*feats, model, machine, rows=slice(y, y + 1),
                        above=above if has_prior(model, machine) else None, results=results)


def right_reference_map(feats: tuple, model: ModelParams, word_bits: int | None) -> np.ndarray:
    return declared_maps(model, *feats, word_bits, band_rows=BAND_ROWS)[RIGHT]


def quantized_band(feats: tuple, model: ModelParams, w: int, rows: slice, above: np.ndarray | None,
                   right_rows: np.ndarray | None) -> Any:
    return reference_quantized(*feats, model, w, rows=rows, above=above,
                               results=None if right_rows is None else {RIGHT: right_rows})
# ---------------------------------------------------------------------------------------------------


def model_of(keywords: dict[str, Any], per_column: bool) -> ModelParams:
    """The model of ``keywords``; ``per_column``: without its fused column if it has one."""
    model = ModelParams(**keywords)
    if per_column and "fuse_columns" in model.to_dict():
        model = ModelParams(**keywords, fuse_columns=False)
    return model


def stereo_rtlil(model: ModelParams, width: int) -> str:
    """The RTLIL without source locations (they move with every edit of the Python)."""
    from amaranth.back import rtlil

    from bayesmachine.hdl.frontend.stereo import StereoMachine, stereo_machine_params

    params = stereo_machine_params(model.dmax, model=model)
    return rtlil.convert(StereoMachine(params=params, model=model, width=width), name="top", emit_src=False)


def _pair(crop: str) -> tuple[np.ndarray, np.ndarray]:
    left, right, _ = bundled_pair()
    x, y, w, h, shift = CROPS[crop]
    return (np.ascontiguousarray(left[y : y + h, x : x + w]),
            np.ascontiguousarray(right[y : y + h, x - shift : x - shift + w]))


def _words(model: ModelParams, machine: Any, feats: tuple, qmap: np.ndarray, rmap_q: np.ndarray | None,
           rmachine: Any) -> dict[str, np.ndarray]:
    """Every map row's words, the prior from the quantized reference's MAPs of the row above."""
    region = OutputRegion.of_features(feats[0].shape, model.dmax, model.margin)
    ho, wo = region.shape
    rows, right_rows = [], []
    for y in range(ho):
        above = np.full(wo, -1, np.int16) if y == 0 else qmap[y - 1]
        if rmap_q is not None:
            r_above = np.full(rmap_q.shape[1], -1, np.int16) if y == 0 else rmap_q[y - 1]
            right_rows.append(right_words(model, rmachine, feats, y, r_above))
        rows.append(own_words(model, machine, feats, y, above, None if rmap_q is None else rmap_q[y]))
    out = {"words": np.stack(rows)}
    if right_rows:
        out["right_words"] = np.stack(right_rows)
    return out


def _references(model: ModelParams, machine: Any, feats: tuple) -> dict[str, np.ndarray]:
    region = OutputRegion.of_features(feats[0].shape, model.dmax, model.margin)
    post, maps = [], []
    for _, band in reference_bands(*feats, model, band_rows=BAND_ROWS):
        post.append(band.posterior.copy())
        maps.append(band.map.copy())
    out = {"ref_posterior": np.concatenate(post), "ref_map": np.concatenate(maps)}
    w = machine.word_bits
    rmap_q = None
    if has_right_pass(model):
        out["ref_right_map"] = right_reference_map(feats, model, None)
        rmap_q = out["qref_right_map"] = right_reference_map(feats, model, w)
    post, maps = [], []
    above = None
    for rows in region.bands(BAND_ROWS):
        band = quantized_band(feats, model, w, rows, above, None if rmap_q is None else rmap_q[rows])
        post.append(band.posterior)
        maps.append(band.map)
        above = band.map[-1].copy()
    out["qref_posterior"], out["qref_map"] = np.concatenate(post), np.concatenate(maps)
    return out


def compute(name: str, per_column: bool = False) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    crop, model_kw, machine_kw = CONFIGS[name]
    left, right = _pair(crop)
    model = model_of(model_kw, per_column)
    machine = disparity_machine(model, **machine_kw)
    rmachine = right_machine(model, machine) if has_right_pass(model) else None
    feats = (model_planes(left, model), model_planes(right, model))
    arrays = _references(model, machine, feats)
    arrays |= _words(model, machine, feats, arrays["qref_map"], arrays.get("qref_right_map"), rmachine)
    prepared = prepare(left, right, model, reference=True)
    arrays["prepared_reference_map"] = prepared.reference_map
    run = run_machine(prepared, machine, "model", progress=False)
    for field in ("map", "counts", "cycles", "nomatch", "timeout"):
        arrays[f"run_{field}"] = getattr(run, field)
    meta: dict[str, Any] = {"model": model.to_dict(), "machine": machine.to_dict(),
                            "right_machine": None if rmachine is None else rmachine.to_dict()}
    for name, record in run.passes.items():
        for field in ("map", "cycles", "timeout"):
            arrays[f"run_{name}_{field}"] = getattr(record, field)
        meta[f"run_{name}_machine"] = record.machine.to_dict()
    return arrays, json.loads(json.dumps(meta))


def compute_rtl(name: str, per_column: bool = False) -> dict[str, Any]:
    model_kw, width = RTL_CONFIGS[name]
    text = stereo_rtlil(model_of(model_kw, per_column), width)
    return {"rtlil_sha256": hashlib.sha256(text.encode()).hexdigest(), "rtlil_chars": len(text)}


def _compare(name: str, got: dict[str, np.ndarray], meta: dict[str, Any], folder: Path) -> list[str]:
    bad = []
    want = np.load(folder / f"{name}.npz")
    for key in sorted(set(want.files) | set(got)):
        if key not in got or key not in want.files:
            bad.append(f"{name}: {key} {'missing now' if key not in got else 'not in the snapshot'}")
            continue
        a, b = np.asarray(got[key]), want[key]
        if a.dtype != b.dtype or a.shape != b.shape:
            bad.append(f"{name}: {key}: {a.dtype} {a.shape}, snapshot {b.dtype} {b.shape}")
        elif not np.array_equal(a, b):  # float64 too: bit for bit (no NaN occurs)
            bad.append(f"{name}: {key}: {int(np.count_nonzero(a != b))} values differ")
    want_meta = json.loads((folder / f"{name}.json").read_text())
    # The model's dict may gain keys (e.g. its name); every value the snapshot recorded stays.
    now_model = {k: v for k, v in meta["model"].items() if k in want_meta["model"]}
    meta = dict(meta, model=now_model)
    for key in sorted(set(want_meta) | set(meta)):
        if want_meta.get(key) != meta.get(key):
            bad.append(f"{name}: {key}: {meta.get(key)} != snapshot {want_meta.get(key)}")
    return bad


def main(argv: list[str] | None = None) -> int:
    ap = Parser(prog=Path(__file__).name, description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("action", choices=("save", "check"))
    ap.add_argument("folder", type=Path)
    ap.add_argument("--only", nargs="*", default=None, help="configurations to save or check (default all)")
    ap.add_argument("--per-column", action="store_true",
                    help="models with a fused column without it (fuse_columns off): one operator column per "
                    "piece of evidence")
    args = ap.parse_args(argv)
    names = args.only or [*CONFIGS, *RTL_CONFIGS]
    unknown = [n for n in names if n not in CONFIGS and n not in RTL_CONFIGS]
    if unknown:
        raise ValueError(f"--only: no configuration {', '.join(unknown)} (they are "
                         f"{', '.join([*CONFIGS, *RTL_CONFIGS])})")
    if args.action == "save":
        args.folder.mkdir(parents=True, exist_ok=True)
    problems: list[str] = []
    for name in names:
        t0 = time.perf_counter()
        if name in RTL_CONFIGS:
            got = compute_rtl(name, args.per_column)
            if args.action == "save":
                atomic_write_text(args.folder / f"{name}.json", json.dumps(got, indent=1) + "\n")
                status = "saved"
            else:
                want = json.loads((args.folder / f"{name}.json").read_text())
                found = [] if want == got else [f"{name}: the RTLIL differs: {got}, snapshot {want}"]
                problems += found
                status = "DIFFERS" if found else "equal"
            print(f"{name:24s} {status} ({time.perf_counter() - t0:.1f} s)")
            continue
        arrays, meta = compute(name, args.per_column)
        if args.action == "save":
            with atomic_file(args.folder / f"{name}.npz") as tmp:  # complete or absent
                np.savez_compressed(tmp, **arrays)
            atomic_write_text(args.folder / f"{name}.json", json.dumps(meta, indent=1, sort_keys=True) + "\n")
            status = "saved"
        else:
            found = _compare(name, arrays, meta, args.folder)
            problems += found
            status = "DIFFERS" if found else "equal"
        print(f"{name:24s} {status} ({len(arrays)} arrays, {time.perf_counter() - t0:.1f} s)")
    for p in problems:
        print(p, file=sys.stderr)
    if problems:
        print(f"golden_snapshot: {len(problems)} differences", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(run_script(Path(__file__).name, main))
