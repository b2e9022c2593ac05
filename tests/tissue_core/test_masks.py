"""Tissue masks in the forms labs' tools write them: images, ImageJ ROIs, polygon CSVs."""

import cv2
import numpy as np
import pytest
import roifile
import tifffile

from tissue_core.errors import InputError
from tissue_core.masks import read_mask

H, W = 60, 80


def _disc(cx=40.0, cy=30.0, r=18.0):
    yy, xx = np.mgrid[:H, :W]
    return (xx - cx) ** 2 + (yy - cy) ** 2 <= r**2


def test_binary_labelled_and_colour_images_mark_the_pixels_that_are_not_zero(tmp_path):
    disc = _disc()
    cv2.imwrite(str(tmp_path / "fiji.png"), disc.astype(np.uint8) * 255)  # Fiji's 0/255
    labels = np.zeros((H, W), np.int32)  # napari's labels: several, any integer type
    labels[disc] = 7
    labels[:5, :5] = 300
    tifffile.imwrite(tmp_path / "labels.tif", labels)
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[disc, 2] = 200  # drawn in red alone (OpenCV's BGR)
    cv2.imwrite(str(tmp_path / "red.png"), rgb)
    rgba = np.zeros((H, W, 4), np.uint8)
    rgba[disc, 3] = 255  # black drawn on transparency: the alpha channel says where
    cv2.imwrite(str(tmp_path / "alpha.png"), rgba)
    planar = np.zeros((3, H, W), np.uint8)
    planar[1][disc] = 9
    tifffile.imwrite(tmp_path / "planar.tif", planar, photometric="rgb", planarconfig="separate")
    floats = disc.astype(np.float32) * 0.5
    tifffile.imwrite(tmp_path / "float.tif", floats)
    gray_alpha = np.zeros((H, W, 2), np.uint8)
    gray_alpha[disc, 1] = 255  # black drawn on transparency, gray + alpha
    tifffile.imwrite(tmp_path / "gray_alpha.tif", gray_alpha, photometric="minisblack",
                     extrasamples=["unassalpha"])  # fmt: skip
    names = ("fiji.png", "red.png", "alpha.png", "planar.tif", "float.tif", "gray_alpha.tif")
    for name in names:
        mask = read_mask(tmp_path / name, (H, W))
        assert mask.kind == "image" and (mask.inside == disc).all(), name
    both = read_mask(tmp_path / "labels.tif", (H, W)).inside
    assert both[disc].all() and both[:5, :5].all() and both.sum() == disc.sum() + 25
    mask = read_mask(tmp_path / "fiji.png", (H, W))
    assert mask.bounds() == (22.0, 12.0, 58.0, 48.0)
    assert mask.fraction == pytest.approx(disc.mean())
    probes = np.array([[40, 30], [22.4, 30.2], [1, 1], [np.nan, 3], [-5, 900]])
    assert mask.contains(probes).tolist() == [True, True, False, False, False]
    summary = mask.summary()
    assert summary["pixels"] == int(disc.sum()) and summary["kind"] == "image"
    # the outline runs along the boundary, between the pixels in and out
    (line,) = mask.outline()
    assert np.allclose(line[0], line[-1])
    radius = np.hypot(line[:, 0] - 40, line[:, 1] - 30)
    assert 17.5 < radius.min() and radius.max() < 19.0


def test_imagej_rois_cover_the_pixels_fiji_fills(tmp_path):
    """Fiji's rectangle at left=10, top=20, 30 x 15 covers columns 10-39 and rows 20-34; an
    oval and a polygon cover the pixels whose centres they hold; a .zip is their union."""
    rect = roifile.ImagejRoi(roitype=roifile.ROI_TYPE.RECT, left=10, top=20, right=40, bottom=35)
    rect.tofile(tmp_path / "rect.roi")
    inside = read_mask(tmp_path / "rect.roi", (H, W)).inside
    expected = np.zeros((H, W), bool)
    expected[20:35, 10:40] = True
    assert (inside == expected).all()
    # a traced polygon (integer corners, as Fiji's polygon tool gives): a right triangle
    tri = roifile.ImagejRoi.frompoints(np.array([[50, 5], [70, 5], [50, 25]], float))
    tri.roitype = roifile.ROI_TYPE.POLYGON
    tri.tofile(tmp_path / "tri.roi")
    inside = read_mask(tmp_path / "tri.roi", (H, W)).inside
    yy, xx = np.mgrid[:H, :W]
    cx, cy = xx + 0.5, yy + 0.5  # ImageJ's pixel centres
    strict = (cx > 50) & (cy > 5) & (cx + cy < 75)
    loose = (cx >= 50) & (cy >= 5) & (cx + cy <= 75)
    assert (inside <= loose).all() and (inside >= strict).all()
    oval = roifile.ImagejRoi(roitype=roifile.ROI_TYPE.OVAL, left=5, top=40, right=25, bottom=56)
    oval.tofile(tmp_path / "oval.roi")
    inside = read_mask(tmp_path / "oval.roi", (H, W)).inside
    inner = ((cx - 15) / 9.5) ** 2 + ((cy - 48) / 7.5) ** 2 <= 1
    outer = ((cx - 15) / 10.5) ** 2 + ((cy - 48) / 8.5) ** 2 <= 1
    assert (inside >= inner).all() and (inside <= outer).all()
    roifile.roiwrite(tmp_path / "set.zip", [rect, tri, oval])
    union = read_mask(tmp_path / "set.zip", (H, W))
    assert union.kind == "imagej-roi"
    parts = [read_mask(tmp_path / n, (H, W)).inside for n in ("rect.roi", "tri.roi", "oval.roi")]
    assert (union.inside == (parts[0] | parts[1] | parts[2])).all()


def test_a_polygon_csv_in_pixel_centres(tmp_path):
    (tmp_path / "p.csv").write_text("x,y\n10,10\n30,10\n30,20\n10,20\n")
    inside = read_mask(tmp_path / "p.csv", (H, W)).inside
    assert inside[10:21, 10:31].all() and inside.sum() == 11 * 21
    # a concave outline: the notch is not tissue
    (tmp_path / "u.csv").write_text("x,y\n5,5\n45,5\n45,45\n35,45\n35,15\n15,15\n15,45\n5,45\n")
    u = read_mask(tmp_path / "u.csv", (H, W)).inside
    assert u[30, 10] and u[30, 40] and not u[30, 25] and u[10, 25]


@pytest.mark.parametrize(
    ("name", "write", "fragments"),
    [
        ("small.png", lambda p: cv2.imwrite(str(p), np.full((H - 1, W), 255, np.uint8)),
         ["small.png is 80x59 px", "80x60 px"]),
        ("blank.png", lambda p: cv2.imwrite(str(p), np.zeros((H, W), np.uint8)),
         ["marks no pixel"]),
        ("mask.jpg", lambda p: cv2.imwrite(str(p), np.zeros((H, W), np.uint8)),
         ["PNG, TIFF", "'.jpg'"]),
        ("text.png", lambda p: p.write_text("no image"), ["not an image"]),
        ("empty.roi", lambda p: p.write_bytes(b""), ["empty"]),
        ("text.roi", lambda p: p.write_text("no roi"), ["not an ImageJ ROI"]),
        ("point.roi", lambda p: roifile.ImagejRoi(roitype=roifile.ROI_TYPE.POINT, left=3,
         top=4, right=4, bottom=5).tofile(p), ["a point ROI", "encloses no area"]),
        ("away.roi", lambda p: roifile.ImagejRoi(roitype=roifile.ROI_TYPE.RECT, left=200,
         top=200, right=300, bottom=300).tofile(p), ["encloses no pixel of the 80x60 px frame"]),
        ("two.csv", lambda p: p.write_text("x,y\n1,1\n5,5\n"), ["2 vertices"]),
        ("nan.csv", lambda p: p.write_text("x,y\n1,1\nnan,5\n9,9\n"), ["finite"]),
        ("words.csv", lambda p: p.write_text("x,y\n1,1\none,5\n9,9\n"), ["line 3"]),
        ("stack.tif", lambda p: tifffile.imwrite(p, np.ones((4, H, W), np.uint8),
         photometric="minisblack"), ["stack of 4"]),
    ],
)  # fmt: skip
def test_a_bad_mask_is_one_clear_error(tmp_path, name, write, fragments):
    path = tmp_path / name
    write(path)
    with pytest.raises((InputError, OSError)) as caught:
        read_mask(path, (H, W))
    message = str(caught.value)
    assert "\n" not in message and name in message, message
    for fragment in fragments:
        assert fragment in message, message
    with pytest.raises(OSError, match="no such file"):
        read_mask(tmp_path / "missing.png", (H, W))
