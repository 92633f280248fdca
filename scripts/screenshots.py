"""Screenshots of the real napari widgets for docs/user-guide.md.

    QT_API=pyqt6 .venv/bin/python scripts/screenshots.py [--out docs/images]

Opens a napari viewer (under a virtual X display started here with
pyvirtualdisplay when ``DISPLAY`` is unset; Xvfb must be installed), loads the
plugin's sample data, docks each widget, runs it as a user would (Run button
-> background worker) and saves what the window shows:

* ``guide-segmentation-before.png`` / ``guide-segmentation-after.png`` - the
  segmentation widget on the "Hand (segmentation)" sample, before and after Run;
* ``guide-segmentation-coins.png`` - the segmentation widget after a run on
  "Coins, real photograph (segmentation)": a rough circle around each coin, and each result.
* ``guide-matching.png`` - the matching widget on "Hand poses (matching)":
  correspondence lines coloured by cost, counts in the widget;
* ``guide-simulation.png`` - the simulation widget and its result on the
  "frame" slider (a middle frame shown);
* ``guide-simulation-frames.png`` - the canvas at every frame of the slider.
* ``guide-tracking.png`` - the tracking widget after a run on the deforming-cell movie, at frame 20.
* ``guide-docked.png`` - all four widgets docked in a 1366 x 768 window (a laptop screen), after a
  segmentation of the hand.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("QT_API", "pyqt6")

ROOT = Path(__file__).resolve().parents[1]
WINDOW = (1500, 900)


def _quiet_napari():
    """Settings in a temporary file (napari saves the window geometry: the user's stay untouched)."""
    import tempfile

    os.environ.setdefault("NAPARI_CONFIG", str(Path(tempfile.mkdtemp(prefix="physeg-shots-")) / "settings.yaml"))
    from napari._qt import qt_main_window

    qt_main_window.SHOW_QT_WARNING = False  # napari's Qt-backend warning pop-up


def _start_display():
    """A virtual display when there is none (returns it, to stop at the end)."""
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or not sys.platform.startswith("linux"):
        return None
    try:
        from pyvirtualdisplay import Display
    except ImportError:
        sys.exit("no DISPLAY and no pyvirtualdisplay: pip install pyvirtualdisplay (and apt install xvfb), "
                 "or run under xvfb-run")
    display = Display(visible=False, size=(WINDOW[0] + 100, WINDOW[1] + 100), color_depth=24)
    display.start()
    return display


def _settle(app, seconds: float = 0.3):
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        app.processEvents()
        time.sleep(0.01)


def _wait(app, widget, timeout: float = 60.0):
    end = time.perf_counter() + timeout
    while widget.is_running:
        if time.perf_counter() > end:
            raise TimeoutError(f"{type(widget).__name__} still running after {timeout} s")
        app.processEvents()
        time.sleep(0.01)
    _settle(app)


def _viewer(napari, title: str):
    viewer = napari.Viewer(title=title, show=True)
    viewer.window._qt_window.resize(*WINDOW)
    return viewer


def _save_window(app, viewer, path: Path):
    from napari._qt.dialogs.qt_notification import NapariQtNotification

    _settle(app, 0.5)
    # the pop-ups of the widgets' notifications would hide part of the canvas
    for toast in viewer.window._qt_window.findChildren(NapariQtNotification):
        toast.hide()
    _settle(app, 0.1)
    viewer.window._qt_window.grab().save(str(path))
    print(f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")


def _zoom_on(viewer, layers, margin: float = 12.0):
    """Fit the camera to the given layers' extent (2D world)."""
    import numpy as np

    lo = np.min([layer.extent.world[0][-2:] for layer in layers], axis=0) - margin
    hi = np.max([layer.extent.world[1][-2:] for layer in layers], axis=0) + margin
    camera = viewer.scene.camera if hasattr(viewer, "scene") else viewer.camera
    camera.center = tuple((lo + hi) / 2)
    canvas = viewer.window._qt_viewer.canvas.size
    size = np.asarray(canvas[::-1] if canvas else (600, 800), dtype=float)
    camera.zoom = float(np.min(size / (hi - lo)))


def segmentation(napari, app, out: Path):
    from napari_physeg._widgets.segmentation import SegmentationWidget

    viewer = _viewer(napari, "napari-physeg: segmentation")
    try:
        viewer.open_sample("napari-physeg", "hand_segmentation")
        widget = SegmentationWidget(viewer)
        viewer.window.add_dock_widget(widget, name="Segmentation (physical contour)", area="right")
        viewer.layers.selection.active = viewer.layers["initial contour"]
        viewer.layers["initial contour"].edge_width = 2.0
        viewer.reset_view()
        _save_window(app, viewer, out / "guide-segmentation-before.png")
        widget._run_btn.native.click()  # as a user would
        _wait(app, widget)
        result = viewer.layers["initial contour segmented (rubber)"]
        result.edge_width = 2.0
        viewer.layers.selection.active = result
        _save_window(app, viewer, out / "guide-segmentation-after.png")
        # A real photograph, in the same window: the coins sample.
        viewer.layers.clear()
        viewer.open_sample("napari-physeg", "coins_segmentation")
        widget._run_btn.native.click()
        _wait(app, widget)
        viewer.layers.selection.active = viewer.layers["circles around the coins segmented (rubber)"]
        viewer.reset_view()
        _save_window(app, viewer, out / "guide-segmentation-coins.png")
    finally:
        viewer.close()


def matching_and_simulation(napari, app, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from napari_physeg._widgets.matching import MatchingWidget
    from napari_physeg._widgets.simulation import SimulationWidget

    viewer = _viewer(napari, "napari-physeg: matching and simulation")
    try:
        viewer.open_sample("napari-physeg", "hand_poses")
        a, b = viewer.layers["hand open outline"], viewer.layers["hand closed outline"]
        for layer in (a, b):
            layer.edge_width = 1.0
            layer.opacity = 0.8
        mwidget = MatchingWidget(viewer)
        mdock = viewer.window.add_dock_widget(mwidget, name="Matching (modal)", area="right")
        mwidget._run_btn.native.click()
        _wait(app, mwidget)
        mlayer = mwidget.output_layer
        mlayer.edge_width = 2.0
        _zoom_on(viewer, [a, b])
        _save_window(app, viewer, out / "guide-matching.png")

        viewer.window.remove_dock_widget(mdock)
        mlayer.visible = False
        swidget = SimulationWidget(viewer)
        viewer.window.add_dock_widget(swidget, name="Simulation (deformation)", area="right")
        swidget._n_frames.value = 8
        swidget._tracks.value = True
        swidget._run_btn.native.click()
        _wait(app, swidget)
        frames_layer = swidget.output_layers[0]
        frames_layer.edge_width = 2.0
        n = len(frames_layer.data)
        viewer.dims.set_current_step(0, n // 2)
        viewer.layers.selection.active = frames_layer
        _zoom_on(viewer, [a, b])
        _save_window(app, viewer, out / "guide-simulation.png")

        # the canvas at each step of the frame slider
        for layer in swidget.output_layers[1:]:
            layer.visible = False
        shots = []
        for t in range(n):
            viewer.dims.set_current_step(0, t)
            _settle(app, 0.2)
            shots.append(viewer.screenshot(canvas_only=True, flash=False))
        cols = 4
        rows = int(np.ceil(n / cols))
        fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.4 * rows), facecolor="black")
        for k, ax in enumerate(np.ravel(axes)):
            ax.set_axis_off()
            if k < n:
                img = shots[k]
                # crop the black margins around the hands
                mask = img[..., :3].max(axis=2) > 20
                rr, cc = np.nonzero(mask)
                pad = 10
                img = img[max(rr.min() - pad, 0):rr.max() + pad, max(cc.min() - pad, 0):cc.max() + pad]
                ax.imshow(img)
                ax.set_title(f"frame {k}", color="white", fontsize=11)
        fig.suptitle("simulation frames on the 'frame' slider: orange = simulated contour, cyan = a, magenta = b",
                     color="white", fontsize=11)
        fig.tight_layout()
        path = out / "guide-simulation-frames.png"
        fig.savefig(path, dpi=90, facecolor="black")
        plt.close(fig)
        print(f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")
    finally:
        viewer.close()


def tracking(napari, app, out: Path):
    from napari_physeg._widgets.tracking import TrackingWidget

    viewer = _viewer(napari, "napari-physeg: tracking")
    try:
        viewer.open_sample("napari-physeg", "deforming_cell")
        widget = TrackingWidget(viewer)
        viewer.window.add_dock_widget(widget, name="Tracking (time-lapse)", area="right")
        viewer.dims.set_point(0, 0)
        viewer.reset_view()
        widget._run_btn.native.click()  # as a user would
        _wait(app, widget, timeout=120.0)
        viewer.layers["contour on frame 0"].visible = False
        viewer.dims.set_point(0, 20)
        viewer.layers.selection.active = widget.output_layers[0]
        _save_window(app, viewer, out / "guide-tracking.png")
    finally:
        viewer.close()


def docked(napari, app, out: Path):
    from napari_physeg._widgets.matching import MatchingWidget
    from napari_physeg._widgets.segmentation import SegmentationWidget
    from napari_physeg._widgets.simulation import SimulationWidget
    from napari_physeg._widgets.tracking import TrackingWidget

    viewer = napari.Viewer(title="napari-physeg: every widget docked", show=True)
    try:
        viewer.window._qt_window.resize(1366, 768)
        viewer.open_sample("napari-physeg", "hand_segmentation")
        widgets = {}
        for cls, name in ((SegmentationWidget, "Segmentation (physical contour)"), (MatchingWidget, "Matching (modal)"),
                          (SimulationWidget, "Simulation (deformation)"), (TrackingWidget, "Tracking (time-lapse)")):
            widgets[name] = cls(viewer)
            viewer.window.add_dock_widget(widgets[name], name=name, area="right")
        viewer.reset_view()
        segment = widgets["Segmentation (physical contour)"]
        segment._run_btn.native.click()
        _wait(app, segment)
        _save_window(app, viewer, out / "guide-docked.png")
    finally:
        viewer.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images", help="output folder")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    display = _start_display()
    if display is not None:
        # Run the viewer in a child process on the virtual display, so that Qt
        # has closed its connection before the display stops.
        import subprocess

        env = dict(os.environ, DISPLAY=display.new_display_var)
        try:
            return subprocess.call([sys.executable, __file__, "--out", str(args.out)], env=env)
        finally:
            display.stop()
    _quiet_napari()
    import napari
    from napari._qt.qt_event_loop import get_qapp

    app = get_qapp()
    segmentation(napari, app, args.out)
    matching_and_simulation(napari, app, args.out)
    tracking(napari, app, args.out)
    docked(napari, app, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
