"""Checks that a rendered PNG is not blank: check_png.py FILE WIDTH HEIGHT.

Exit 0 when the image has the given size, at least 16 distinct colours and at least 5 % of
its pixels differ from the most common colour (the background); else prints why and exits 1.
Run with Debian's /usr/bin/python3 (numpy, matplotlib).
"""
import sys

import matplotlib.image as mpimg
import numpy as np


def main(path, width, height):
    img = mpimg.imread(path)  # float RGB(A) in [0, 1]
    rgb = np.round(np.asarray(img)[..., :3] * 255).astype(np.uint8)
    h, w = rgb.shape[:2]
    colours, counts = np.unique(rgb.reshape(-1, 3), axis=0, return_counts=True)
    background = colours[np.argmax(counts)]
    share = 1.0 - counts.max() / float(h * w)
    print("%s: %d x %d, %d colours, background %s, %.1f %% of the pixels differ from it"
          % (path, w, h, len(colours), background.tolist(), 100 * share))
    problems = []
    if (w, h) != (width, height):
        problems.append("size %d x %d, expected %d x %d" % (w, h, width, height))
    if len(colours) < 16:
        problems.append("only %d colours" % len(colours))
    if share < 0.05:
        problems.append("only %.2f %% of the pixels differ from the background" % (100 * share))
    for p in problems:
        print("not a rendered run: " + p)
    return 1 if problems else 0


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3])))
