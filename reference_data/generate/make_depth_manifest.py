"""The rooms' truth depths: stored ZIP-compressed, and a manifest of their decoded bits.

For every `scenes/<room>/depth/<name>.exr` this decodes channel Y with OpenEXR (the format's
reference library), re-writes a file stored with another compression as ZIP
(`common.write_depth_exr`, lossless: the re-written file must decode to the same bits or
the script stops), and writes `scenes/<room>/depth/decoded-sha256.txt`: one line per file,
`<SHA-256 of the decoded float32 samples, little-endian, row-major>  <name>.exr`, the hash
taken from the file as found (before any re-write). The engine's test
`scene_depths_decode_to_the_bits_openexr_decodes` (tests/engine/readers.rs) reads every file
with unseen's EXR reader and compares: a re-encoding that changed one bit, or a reader that
decodes one differently, fails it.

Run after make_scenes.py, make_bridge_views.py or make_candidate_families.py (which write
ZIP already; this then only refreshes the manifest). Needs only numpy and OpenEXR
(requirements.txt).
"""
import glob
import hashlib
import os
import sys

import numpy as np
import OpenEXR

sys.path.insert(0, os.path.dirname(__file__))
from common import write_depth_exr  # noqa: E402

SCENES = os.path.join(os.path.dirname(__file__), "..", "scenes")
MANIFEST = "decoded-sha256.txt"


def decode(path):
    """(compression, channel Y as float32 (H, W))."""
    with OpenEXR.File(path) as f:
        compression = f.header()["compression"]
        channels = f.channels()
        if list(channels) != ["Y"]:
            raise SystemExit(f"{path}: channels {list(channels)}, want Y alone")
        y = np.ascontiguousarray(channels["Y"].pixels)
    if y.dtype != np.float32:
        raise SystemExit(f"{path}: {y.dtype}, want float32")
    return compression, y


def main():
    rewritten = 0
    for room in sorted(os.listdir(SCENES)):
        folder = os.path.join(SCENES, room, "depth")
        if not os.path.isdir(folder):
            continue
        lines = []
        for path in sorted(glob.glob(os.path.join(folder, "*.exr"))):
            compression, y = decode(path)
            digest = hashlib.sha256(y.astype("<f4").tobytes()).hexdigest()
            if compression != OpenEXR.ZIP_COMPRESSION:
                write_depth_exr(path, y)
                _, again = decode(path)
                if not np.array_equal(again.view(np.uint32), y.view(np.uint32)):
                    raise SystemExit(f"{path}: the ZIP file decodes to other bits")
                rewritten += 1
            lines.append(f"{digest}  {os.path.basename(path)}\n")
        with open(os.path.join(folder, MANIFEST), "w") as f:
            f.writelines(lines)
        print(f"{room}: {len(lines)} depths")
    print(f"re-written as ZIP: {rewritten}; OpenEXR {OpenEXR.__version__}")


if __name__ == "__main__":
    main()
