"""`python -m rendering CLIP.npz OUT.mp4 [--size 640] [--sheet OUT.png]`: render one clip file."""

import sys
from pathlib import Path

from moglow_eval.core import cli
from rendering.errors import RenderError
from rendering.mesh import set_gl_environment
from rendering.render import MAX_SIZE, MIN_SIZE, RenderOptions, render_clip, size_flag

PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow")


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    p = cli.ArgumentParser(prog="python -m rendering", description=__doc__)
    p.add_argument("clip", help="motion clip .npz (CONTRACTS.md §1)")
    p.add_argument("out", help="output .mp4")
    p.add_argument(
        "--size",
        type=size_flag,
        default=640,
        help=f"frame width = height in pixels, even, {MIN_SIZE}-{MAX_SIZE} (default 640)",
    )
    p.add_argument("--sheet", help="also write a PNG contact sheet here")
    p.add_argument("--preset", default="ultrafast", choices=PRESETS, help="x264 preset (default ultrafast)")
    p.add_argument(
        "--qp",
        type=cli.number(int, 0, 51),
        help="x264 constant quantiser, 0-51, lower is better, instead of the default constant bit rate (every "
        "frame one coded size, as in a stimulus set)",
    )
    p.add_argument("--crf", type=cli.number(int, 0, 51), help="x264 rate factor 0-51 instead of the constant bit rate")
    return p


def _main(argv):
    args = build_parser().parse_args(argv)
    if not Path(args.clip).is_file():
        raise RenderError(f"{args.clip}: {'not a file' if Path(args.clip).exists() else 'no such file'}")
    # Every output path checked before the first frame: a bad one would otherwise fail after the video is written.
    for flag, path in (("OUT", args.out), ("--sheet", args.sheet)):
        if path is None:
            continue
        if not Path(path).parent.is_dir():
            raise RenderError(f"{flag} {path}: folder {Path(path).parent} does not exist")
        if Path(path).is_dir():
            raise RenderError(f"{flag} {path}: is a folder; give a file name")
        if Path(path).exists() and Path(path).samefile(args.clip):
            raise RenderError(f"{flag} {path}: is the clip itself")
    options = RenderOptions(size=args.size, preset=args.preset, qp=args.qp, crf=args.crf)
    n = render_clip(args.clip, args.out, options, sheet=args.sheet)
    print(f"wrote {args.out} ({n} frames, {args.size}x{args.size})")


def main(argv=None):
    set_gl_environment()  # the process's own setting, so here and not in the library
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
