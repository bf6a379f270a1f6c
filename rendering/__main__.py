"""`python -m rendering CLIP.npz OUT.mp4 [--size 640] [--sheet OUT.png]`: render one clip file."""
import argparse
import sys
from pathlib import Path

from generation.clip import ClipError
from rendering.render import RenderError, render_clip


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m rendering", description=__doc__)
    p.add_argument("clip", help="motion clip .npz (CONTRACTS.md §1)")
    p.add_argument("out", help="output .mp4")
    p.add_argument("--size", type=int, default=640, help="frame width = height in pixels (even)")
    p.add_argument("--sheet", help="also write a PNG contact sheet here")
    p.add_argument("--preset", default="ultrafast", help="x264 preset (ultrafast ... veryslow; default ultrafast)")
    p.add_argument("--qp", type=int, default=17, help="x264 constant quantiser, 0-51, lower is better (default 17)")
    p.add_argument("--crf", type=int, help="x264 rate factor instead of a constant quantiser (lower is better)")
    args = p.parse_args(argv)
    try:
        if not Path(args.clip).is_file():
            raise RenderError(f"{args.clip}: no such file")
        if not Path(args.out).parent.is_dir():
            raise RenderError(f"{args.out}: folder {Path(args.out).parent} does not exist")
        n = render_clip(args.clip, args.out, size=args.size, sheet=args.sheet, preset=args.preset,
                        qp=args.qp, crf=args.crf)
    except (ClipError, RenderError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {args.out} ({n} frames, {args.size}x{args.size})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
