"""napari-physeg demo: the whole pipeline on the bundled synthetic sample data.

Without a display it writes figures and a short table to ``demo_output/``;
with a display (``DISPLAY`` set, or ``--gui``) it then opens napari with the
plugin's widgets docked and the sample data loaded.

    make demo                       # set up everything, then run this
    .venv/bin/python scripts/demo.py [--out DIR] [--gui | --no-gui]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from skimage.draw import polygon2mask  # noqa: E402

from napari_physeg import data  # noqa: E402
from napari_physeg.core import segment  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def stage(msg: str) -> None:
    print(f"==> {msg}", flush=True)


def closed(c: np.ndarray) -> np.ndarray:
    return np.vstack([c, c[:1]])


def iou(contour, mask) -> float:
    m = polygon2mask(mask.shape, contour)
    return float((m & mask).sum() / (m | mask).sum())


def plot_segmentation(ax, obj, res, title):
    ax.imshow(obj.image, cmap="gray")
    for h in res.history[1:-1:max(1, len(res.history) // 8)]:
        ax.plot(*closed(h)[:, ::-1].T, color="tab:cyan", lw=0.6, alpha=0.7)
    ax.plot(*closed(res.history[0])[:, ::-1].T, color="tab:orange", lw=1.2, label="initial contour")
    ax.plot(*closed(res.contour)[:, ::-1].T, color="tab:red", lw=1.4, label="result")
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()


def run_segmentation(out: Path) -> list[tuple]:
    stage("segmentation: hand (sample data), from a contour drawn near it and from one far outside")
    rows = []
    fig, axes = plt.subplots(1, 3, figsize=(12, 4.3))
    cases = [
        ("hand, near", data.hand(noise=0.05), "init_near", {}),
        ("hand, far", data.hand(noise=0.05), "init_far", {}),
        ("dark blob, copper", data.blob(bright=False, noise=0.1), "init_far",
         dict(material="copper", stiffness=1e6)),
    ]
    for ax, (name, obj, which, kw) in zip(axes, cases):
        t0 = time.perf_counter()
        res = segment(obj.image, getattr(obj, which), **kw)
        elapsed = time.perf_counter() - t0
        score = iou(res.contour, obj.mask)
        rows.append((name, res.n_nodes, res.steps, elapsed * 1e3, score))
        print(f"    {name:18s} {res.n_nodes:4d} nodes {res.steps:4d} steps {elapsed * 1e3:7.0f} ms  IoU {score:.3f}")
        plot_segmentation(ax, obj, res, f"{name}: {res.steps} steps, {elapsed * 1e3:.0f} ms, IoU {score:.3f}")
    axes[0].legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    path = out / "segmentation.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"    wrote {path}")
    return rows


def write_table(out: Path, rows) -> None:
    lines = ["| case | nodes | steps | time (ms) | IoU |", "|---|---|---|---|---|"]
    lines += [f"| {n} | {k} | {s} | {t:.0f} | {q:.3f} |" for n, k, s, t, q in rows]
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def open_napari() -> None:
    stage("opening napari with the napari-physeg widgets and sample data")
    import napari

    viewer = napari.Viewer()
    try:
        viewer.open_sample("napari-physeg", "hand_segmentation")
        viewer.window.add_plugin_dock_widget("napari-physeg")
    except Exception as err:  # the plugin's widgets may not all exist yet
        print(f"    (could not load every widget: {err})")
    napari.run()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "demo_output", help="folder for figures")
    gui = ap.add_mutually_exclusive_group()
    gui.add_argument("--gui", action="store_true", help="open napari afterwards")
    gui.add_argument("--no-gui", action="store_true", help="never open napari")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = run_segmentation(args.out)
    write_table(args.out, rows)
    print(f"\nFigures and summary are in {args.out}")
    if args.gui or (not args.no_gui and os.environ.get("DISPLAY") and not os.environ.get("CI")):
        open_napari()
    return 0


if __name__ == "__main__":
    sys.exit(main())
