"""napari sample data (File > Open Sample > napari-physeg).

Each function returns a list of napari LayerData tuples ``(data, kwargs,
layer_type)``; the arrays come from :mod:`napari_physeg.data`. Shapes layers
hold float32 ``(row, col)`` polygons in the pixel coordinates of the 256 x 256
hand images, so they overlay them.
"""

from __future__ import annotations

import numpy as np

from . import data

__all__ = ["hand_segmentation", "hand_poses", "hand_open_image", "hand_closed_image", "deforming_cell",
           "coins_segmentation"]

_CONTOUR_STYLE = {"shape_type": "polygon", "face_color": "transparent", "edge_width": 1.5}


def _polygon_layer(contour, name: str, color: str) -> tuple:
    return ([np.asarray(contour, dtype=np.float32)], {"name": name, "edge_color": color, **_CONTOUR_STYLE},
            "shapes")


def hand_segmentation() -> list[tuple]:
    """A noisy 256 x 256 image of an open hand and an initial contour around it.

    Open the segmentation widget and press Run to see the contour move onto the hand.
    """
    image, init = data.sample_segmentation()
    # The core resamples the contour (a node every ~3 px); fewer vertices keep
    # the Shapes layer light to draw and edit.
    init = init[::3]
    return [
        (image.astype(np.float32), {"name": "hand", "colormap": "gray"}, "image"),
        _polygon_layer(init, "initial contour", "yellow"),
    ]


def hand_poses() -> list[tuple]:
    """Outlines of the hand in two poses, open and closed, for modal matching.

    Both are placed on the same 256 x 256 image as the hand images (the samples
    "Hand, open (image)" and "Hand, closed (image)"); 67 and 66 nodes, as in
    the paper's experiment.
    """
    open_, closed, _ = data.hand_pair(pose_a="open", pose_b="closed")
    return [
        _polygon_layer(open_, "hand open outline", "cyan"),
        _polygon_layer(closed, "hand closed outline", "magenta"),
    ]


def _hand_image(pose: str) -> list[tuple]:
    obj = data.hand((256, 256), pose=pose, noise=0.05, seed=0)
    return [(obj.image.astype(np.float32), {"name": f"hand {pose}", "colormap": "gray"}, "image")]


def hand_open_image() -> list[tuple]:
    """A 256 x 256 image of the open hand."""
    return _hand_image("open")


def hand_closed_image() -> list[tuple]:
    """A 256 x 256 image of the closed hand."""
    return _hand_image("closed")


def deforming_cell() -> list[tuple]:
    """A 30-frame movie of a cell that drifts, turns and protrudes, and a
    contour drawn around it on frame 0.

    Open the Tracking widget, stay on frame 0 and press Run.
    """
    movie = data.deforming_cell()
    init = np.column_stack([np.zeros(len(movie.init[::3])), movie.init[::3]])
    return [
        (movie.frames.astype(np.float32), {"name": "deforming cell", "colormap": "gray"}, "image"),
        ([init.astype(np.float32)], {"name": "contour on frame 0", "edge_color": "yellow", **_CONTOUR_STYLE},
         "shapes"),
    ]


#: A circle (row, col, radius) dragged around each coin of
#: ``skimage.data.coins()`` with napari's ellipse tool, as people draw them:
#: 1.15-1.35 times the coin's radius, a few pixels off its centre, some
#: crossing a neighbour (placed from scikit-image's gallery segmentation of
#: the coins, row by row).
COIN_CIRCLES = ((55, 43, 25), (56, 99, 23), (52, 157, 30), (50, 215, 30), (53, 278, 26), (44, 336, 37),
                (126, 45, 25), (125, 102, 23), (126, 153, 21), (124, 204, 23), (118, 270, 33), (126, 335, 26),
                (198, 44, 22), (196, 102, 28), (197, 155, 23), (192, 214, 28), (194, 273, 26), (184, 346, 37),
                (263, 46, 36), (267, 114, 25), (260, 173, 33), (262, 245, 31), (262, 300, 33), (267, 358, 25))


def coins_segmentation() -> list[tuple]:
    """scikit-image's coins (a real photograph, 303 x 384) and a rough circle
    around each of its 24 coins, in a Shapes layer of ellipses.

    Open the segmentation widget and press Run: each circle comes to rest
    on its coin's border.
    """
    from skimage.data import coins

    ellipses = [np.array([[r - s, c - s], [r - s, c + s], [r + s, c + s], [r + s, c - s]], dtype=np.float32)
                for r, c, s in COIN_CIRCLES]
    return [
        (coins(), {"name": "coins", "colormap": "gray"}, "image"),
        (ellipses, {"name": "circles around the coins", "edge_color": "yellow",
                    **{**_CONTOUR_STYLE, "shape_type": "ellipse"}}, "shapes"),
    ]

