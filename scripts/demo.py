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
from napari_physeg.core import match, segment, simulate  # noqa: E402

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


def plot_matching(ax, a, b, m, title):
    costs = np.asarray(m.cost, dtype=float)
    norm = plt.Normalize(costs.min(), costs.max() if costs.max() > costs.min() else costs.min() + 1)
    for (i, j), c in zip(m.pairs, costs):
        ax.plot([a[i, 1], b[j, 1]], [a[i, 0], b[j, 0]], color=plt.cm.viridis(norm(c)), lw=0.8)
    ax.plot(*closed(a)[:, ::-1].T, "k.-", lw=1, ms=3)
    ax.plot(*closed(b)[:, ::-1].T, ".-", color="tab:red", lw=1, ms=3)
    if len(m.unmatched):
        ax.plot(a[m.unmatched, 1], a[m.unmatched, 0], "o", mfc="none", mec="tab:orange", ms=6, label="unmatched")
        ax.legend(loc="lower left", fontsize=8)
    ax.set_title(title, fontsize=9)
    ax.invert_yaxis()
    ax.set_aspect("equal")
    ax.set_axis_off()


def plot_simulation(ax, sim, a, b, title):
    for f in sim.frames[1:-1]:
        ax.plot(*closed(f)[:, ::-1].T, color="0.6", lw=0.8)
    ax.plot(*closed(a)[:, ::-1].T, "k", lw=1.2)
    ax.plot(*closed(b)[:, ::-1].T, "k", lw=1.2)
    ax.set_title(title, fontsize=9)
    ax.invert_yaxis()
    ax.set_aspect("equal")
    ax.set_axis_off()


def run_matching_and_simulation(out: Path) -> list[tuple]:
    stage("matching and simulation: the hand in two poses (67 and 66 nodes, as in the paper's figs. 8-11)")
    open_hand, closed_hand = data.hand(pose="open", noise=0.05), data.hand(pose="spread", noise=0.05)
    # Segment both poses first, as the paper does, then resample to its node counts.
    from napari_physeg.core.contour import resample

    a = resample(segment(open_hand.image, open_hand.init_near).contour, 67)
    b = resample(segment(closed_hand.image, closed_hand.init_near).contour, 66)
    rows = []
    fig, axes = plt.subplots(2, 2, figsize=(10, 10))
    sims = {}
    # The default method (order) and the paper's (local, mutual minima, eq. 18 for the rest).
    for row, method in zip(axes, ("order", "local")):
        t0 = time.perf_counter()
        m = match(a, b, method=method)
        t_match = time.perf_counter() - t0
        t0 = time.perf_counter()
        sim = simulate(a, b, m, q=30000.0, n_frames=7)
        t_sim = time.perf_counter() - t0
        sims[method] = sim
        rows.append((f"match ({method}) + simulate", len(a), sim.steps, (t_match + t_sim) * 1e3,
                     f"{len(m.pairs)} of {len(a)} matched"))
        print(f"    {method:6s}: {len(m.pairs)} of {len(a)} nodes matched in {t_match * 1e3:.0f} ms, "
              f"simulation {sim.steps} steps in {t_sim * 1e3:.0f} ms")
        plot_matching(row[0], a, b, m, f"{method} matching: {len(m.pairs)} of {len(a)} nodes matched "
                      "(colour: match cost)")
        plot_simulation(row[1], sim, a, b, f"simulation with eq. {'17 + 18' if method == 'local' else '17'}, "
                        "q = 30000 N/m (grey: intermediate shapes)")
    fig.tight_layout()
    path = out / "matching_simulation.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    print(f"    wrote {path}")
    write_gif(out / "simulation.gif", sims["order"], open_hand.image)
    return rows


def write_gif(path: Path, sim, background) -> None:
    from matplotlib.animation import FuncAnimation, PillowWriter

    fig, ax = plt.subplots(figsize=(4, 4))
    ax.imshow(background, cmap="gray", alpha=0.35)
    ax.set_axis_off()
    (line,) = ax.plot([], [], color="tab:red", lw=2)
    frames = list(sim.frames) + [sim.frames[-1]] * 3 + list(sim.frames[::-1]) + [sim.frames[0]] * 3

    def draw(k):
        line.set_data(*closed(frames[k])[:, ::-1].T)
        return (line,)

    FuncAnimation(fig, draw, frames=len(frames), blit=True).save(path, writer=PillowWriter(fps=6))
    plt.close(fig)
    print(f"    wrote {path}")


def write_table(out: Path, rows) -> None:
    lines = ["| stage | nodes | steps | time (ms) | IoU / matched |", "|---|---|---|---|---|"]
    lines += [f"| {n} | {k} | {s} | {t:.0f} | {q if isinstance(q, str) else f'{q:.3f}'} |"
              for n, k, s, t, q in rows]
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def open_napari() -> None:
    stage("opening napari with the napari-physeg widgets and sample data")
    import napari

    viewer = napari.Viewer()
    viewer.open_sample("napari-physeg", "hand_segmentation")
    viewer.open_sample("napari-physeg", "hand_poses")
    for k, name in enumerate(("Segmentation (physical contour)", "Matching (modal)", "Simulation (deformation)")):
        viewer.window.add_plugin_dock_widget("napari-physeg", name, tabify=k > 0)
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
    rows += run_matching_and_simulation(args.out)
    write_table(args.out, rows)
    print(f"\nFigures and summary are in {args.out}")
    if args.gui or (not args.no_gui and os.environ.get("DISPLAY") and not os.environ.get("CI")):
        open_napari()
    return 0


if __name__ == "__main__":
    sys.exit(main())
