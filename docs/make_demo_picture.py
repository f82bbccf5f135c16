"""docs/demo.png, the README's picture, from a finished `cargo run --release -- demo`:
per evaluation view, the truth | the original scene's render | the final scene's render
(80x60 each, the demo's evaluation renders, enlarged 2x nearest). Needs Pillow."""
import os
import sys

from PIL import Image

EVAL = os.path.join(sys.argv[1] if len(sys.argv) > 1 else "demo-out", "extrapolate", "eval")
VIEWS = ["bridge_001", "bridge_003"]
W, H = 80, 60  # each eval PNG is render | truth side by side

strip = Image.new("RGB", (3 * W, H * len(VIEWS)))
for i, view in enumerate(VIEWS):
    original = Image.open(os.path.join(EVAL, "original", view + ".png"))
    final = Image.open(os.path.join(EVAL, "interpolate", view + ".png"))
    for k, (img, x) in enumerate([(original, W), (original, 0), (final, 0)]):
        strip.paste(img.crop((x, 0, x + W, H)), (k * W, i * H))
out = os.path.join(os.path.dirname(__file__), "demo.png")
strip.resize((2 * strip.width, 2 * strip.height), Image.NEAREST).save(out, optimize=True)
print(out)
