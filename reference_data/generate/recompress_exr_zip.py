"""Re-encode PIZ-compressed golden EXRs as ZIP, losslessly, where that makes the file smaller.

Mitsuba's Bitmap writer (which wrote the Dr.Jit raster goldens before `common.write_exr`
switched to ZIP) stores PIZ. On these float32 renders PIZ gains nothing: a one-channel
160x120 file takes 77 185 bytes, the raw samples plus the header. ZIP (zlib over 16-line
blocks after OpenEXR's byte split and delta predictor) was 0.6 % smaller over the 30 raster
EXRs, ZIPS (one line per block) 3.6 % larger. ZIP is smaller for 21 of them and written only
there: 1 903 900 -> 1 877 295 bytes (-1.4 %).

For each `*.exr` under the given folders or files (default: reference_data/drjit) stored with
PIZ, this reads every channel with its pixel type, writes it again with ZIP and the same
header (channel names, data and display windows, `generatedBy` and the other attributes),
reads the new file back and stops unless every channel's raw bytes (NaNs included) and every
attribute but the compression equal the original's. The file is replaced only if the new one
is smaller; otherwise the PIZ original stays. Files stored otherwise are skipped: a second
run changes nothing. Needs only numpy and OpenEXR (requirements.txt).

Run:  python recompress_exr_zip.py [PATH ...]
"""
import glob
import os
import sys

import numpy as np
import OpenEXR

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT = [os.path.normpath(os.path.join(HERE, "..", "drjit"))]


def load(path):
    """(header without its channel list, {name: contiguous samples}) as OpenEXR decodes them."""
    with OpenEXR.File(path, separate_channels=True) as f:
        header = {k: v for k, v in f.header().items() if k != "channels"}
        channels = {k: np.ascontiguousarray(c.pixels) for k, c in f.channels().items()}
    return header, channels


def same_attribute(a, b):
    if isinstance(a, tuple) or isinstance(b, tuple):
        return len(a) == len(b) and all(same_attribute(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    return a == b


def check_same(path, header, channels, header2, channels2):
    if list(channels2) != list(channels):
        raise SystemExit(f"{path}: channels {list(channels2)}, want {list(channels)}")
    for name, x in channels.items():
        y = channels2[name]
        if y.dtype != x.dtype or y.shape != x.shape or y.tobytes() != x.tobytes():
            raise SystemExit(f"{path}: channel {name} decodes to other bits after re-encoding")
    for key in set(header) | set(header2):
        if key == "compression":
            continue
        if key not in header or key not in header2:
            raise SystemExit(f"{path}: attribute {key} lost or added by re-encoding")
        if not same_attribute(header[key], header2[key]):
            raise SystemExit(f"{path}: attribute {key} {header[key]!r} -> {header2[key]!r}")


def recompress(path):
    """(size before, size after, replaced?)."""
    header, channels = load(path)
    before = os.path.getsize(path)
    if header["compression"] != OpenEXR.PIZ_COMPRESSION:
        return before, before, False
    tmp = path + ".zip.tmp"
    new_header = dict(header, compression=OpenEXR.ZIP_COMPRESSION)
    # The writer takes the dict's arrays over as Channel objects: give it a copy.
    OpenEXR.File(new_header, dict(channels)).write(tmp)
    try:
        header2, channels2 = load(tmp)
        if header2["compression"] != OpenEXR.ZIP_COMPRESSION:
            raise SystemExit(f"{tmp}: compression {header2['compression']}, want ZIP")
        check_same(path, header, channels, header2, channels2)
        after = os.path.getsize(tmp)
        if after < before:
            os.replace(tmp, path)
            return before, after, True
        return before, before, False
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def main():
    paths = []
    for arg in sys.argv[1:] or DEFAULT:
        if os.path.isdir(arg):
            paths += sorted(glob.glob(os.path.join(arg, "**", "*.exr"), recursive=True))
        else:
            paths.append(arg)
    total_before = total_after = replaced = 0
    for path in paths:
        before, after, done = recompress(path)
        total_before += before
        total_after += after
        replaced += done
        print(f"{path}: {before} -> {after}" + ("" if done else " (kept)"))
    print(f"{replaced} of {len(paths)} files re-written as ZIP; EXR bytes {total_before} -> "
          f"{total_after}; OpenEXR {OpenEXR.__version__}")


if __name__ == "__main__":
    main()
