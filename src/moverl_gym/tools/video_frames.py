#!/usr/bin/env python3
"""A strip of frames from a recorded episode (an mp4 of RecordVideo, train.py --video or evaluate.py --video), evenly
spaced from the first to the last frame, side by side in one PNG (for READMEs and reports).

    python src/moverl_gym/tools/video_frames.py runs/<run>/videos/eval-episode-1.mp4 out.png --n 4
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("video", help="mp4 file")
    p.add_argument("out", help="PNG to write")
    p.add_argument("--n", type=int, default=4, help="frames in the strip")
    p.add_argument("--crop", type=float, default=0.125, help="share of the width and height cut from each border")
    args = p.parse_args(argv)
    if args.n < 1 or not 0 <= args.crop < 0.5:
        print("--n must be >= 1 and 0 <= --crop < 0.5", file=sys.stderr)
        return 2
    import imageio.v3 as iio
    from PIL import Image

    frames = iio.imread(args.video)
    idx = np.linspace(0, len(frames) - 1, args.n).round().astype(int)
    h, w = frames.shape[1:3]
    dy, dx = int(h * args.crop), int(w * args.crop)
    strip = np.concatenate([frames[i][dy : h - dy, dx : w - dx] for i in idx], axis=1)
    Image.fromarray(strip).save(args.out)
    print(f"{args.out}: frames {idx.tolist()} of {len(frames)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
