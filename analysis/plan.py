"""`python -m analysis.plan PILOT.csv`: how many raters a rating study needs, from a pilot.

Fits the report's linear mixed model (rating ~ condition + (1|rater) + (1|clip)) on the pilot's kept test rows
and simulates whole studies from the fitted condition means and variance components (a parametric bootstrap):
each simulated rater rates `clips_per_rater` clips drawn at random, as the app assigns them. Every simulated
study is analysed with the report's own decision -- Tukey HSD at family-wise alpha over all conditions -- and
power is the share of studies in which the chosen pair differs. Answers: how many raters give power 0.8
(--power) to detect the pilot's difference (or --difference) between two conditions, and (--raters) what
power a given design has. Covers the acr design only (pairwise and parallel designs have no planner yet).

Why simulate rather than a formula: raters see a random subset of clips and both raters and clips vary, so the
variance of a difference of condition means has no closed form that also covers Tukey's pooled error and
critical value. The simulation is vectorised over studies (a chunk of studies is one set of array operations),
and the same random numbers serve every design size, so the power curve is smooth and monotone up to noise.

Caveat printed with every plan: Tukey HSD treats ratings as independent, while clips vary. The table also gives
the false-positive rate of that decision at the planned size (difference 0); with many raters per clip it can
exceed alpha, and then the mixed model's test in the report (Satterthwaite df) is the one to trust. So every plan
also gives the power of a decision that counts the clips as the sample they are (Tukey HSD on the clips' mean
ratings, whose false-positive rate stays at alpha): the raters it needs, or, where the clips' own spread keeps it
from the target however many raters come, that more clips are needed.
"""

import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm import tqdm

from moglow_eval.core import cli, whole_files

from .data.filtering import DEFAULT_THRESHOLD, exclude_raters, only_test_rows
from .data.load import AnalysisError, load_ratings
from .page import figures
from .stats import rating_models
from .stats.power import simulate_power, with_difference

MAX_RATERS = 5000


def pilot_design(test):
    """The design and fitted model of a pilot's test rows: what `simulate_power` and `plan` draw new studies from.

    Parameters
    ----------
    test : DataFrame
        The pilot's test ratings (columns rater_id, clip_id, condition, rating), raters already excluded.

    Returns
    -------
    dict
        conditions; means (model-based, per condition); sd_rater, sd_clip and sd_residual from the linear
        mixed model; clips_per_condition; clips_per_rater (the median ratings per rater); n_raters.

    Raises
    ------
    ModelUndefined
        The pilot cannot identify the mixed model (see `mixed_model`).
    """
    m = rating_models.mixed_model(test)
    vc = m["variance_components"]
    conds = list(m["condition_means"])
    return {
        "conditions": conds,
        "means": m["condition_means"],
        "sd_rater": math.sqrt(vc["rater"]),
        "sd_clip": math.sqrt(vc["clip"]),
        "sd_residual": math.sqrt(vc["residual"]),
        "clips_per_condition": int(round(test.groupby("condition")["clip_id"].nunique().mean())),
        "clips_per_rater": int(round(test.groupby("rater_id").size().median())),
        "n_raters": int(test["rater_id"].nunique()),
    }


def plan(
    design, pair, target=0.8, n_sim=1000, alpha=0.05, seed=0, raters=None, max_raters=MAX_RATERS, progress=True,
    clip_test=True,
):  # fmt: skip
    """The power curve over the number of raters, and the smallest number that reaches `target`.

    Parameters
    ----------
    design : dict
        As from `pilot_design` (its means may be changed to plan for another difference).
    pair : tuple of str
        The two conditions compared.
    target : float
        The power wanted.
    n_sim : int
        The studies simulated at each size.
    alpha : float
        The family-wise error rate of the test.
    seed : int
        The seed of the simulations.
    raters : int or None
        A number of raters whose power is also wanted.
    max_raters : int
        The search stops here.
    progress : bool
        Show a progress bar on stderr.
    clip_test : bool
        Also plan the decision on the clips' mean ratings (the result's clip_test; None without it).

    Returns
    -------
    dict
        curve, a DataFrame (raters, ratings_per_clip, power, low, high; with `clip_test` also clip_power,
        clip_low, clip_high) with a row per size evaluated;
        planned_raters (None when `max_raters` does not reach the target) and planned_power; power_at
        {raters: power} for `raters`; false_positive_rate, the power with a difference of 0 at the planned size
        (or at `raters`); clip_test, the same for Tukey's HSD on the clips' mean ratings (simulate_power's
        `unit="clip"`): {"max_power" (with every clip rated by endless raters: the clips' own spread alone),
        "planned_raters" (None where max_power falls short of `target`), "power_at_check" (its power at the
        planned size, or at `raters`)}.

    Notes
    -----
    The search doubles the number of raters until the target is reached, then bisects between the last two
    sizes; every size evaluated is a row of the curve.
    """
    per_clip_per_rater = design["clips_per_rater"] / (len(design["conditions"]) * design["clips_per_condition"])
    bar = tqdm(desc="simulated studies", unit="study", disable=not progress, file=sys.stderr, leave=False)

    def power_of(unit, rows):
        def power(r):
            if r not in rows:
                rows[r] = simulate_power(design, pair, r, n_sim, alpha, seed, progress=bar, unit=unit)
            return rows[r][0]

        return power

    rows = {}
    power = power_of("rating", rows)
    planned = _fewest_raters(power, target, max_raters)
    if planned:
        for r in np.unique(np.linspace(2, max(4, int(planned * 1.5)), 10).astype(int)):  # a readable curve
            power(int(r))
    if raters is not None:
        power(int(raters))
    out = {
        "planned_raters": planned,
        "planned_power": rows[planned][0] if planned else None,
        "power_at": {int(raters): rows[int(raters)][0]} if raters is not None else {},
    }
    null_design = with_difference(design, pair, 0.0)
    check = planned or raters
    if check:
        out["false_positive_rate"] = simulate_power(
            null_design, pair, int(check), n_sim, alpha, seed + 1, progress=bar
        )[0]
    clip_rows = {}
    columns = ["raters", "ratings_per_clip", "power", "low", "high"]
    if clip_test:
        clip_power = power_of("clip", clip_rows)
        out["clip_test"] = _clip_test(design, pair, target, n_sim, alpha, seed, check, max_raters, clip_power, bar)
        for r in rows:  # the clips' decision at every size of the curve, for the figure
            clip_power(r)
        columns += ["clip_power", "clip_low", "clip_high"]
    else:
        out["clip_test"] = None
    bar.close()
    curve = pd.DataFrame(
        [(r, r * per_clip_per_rater, *v, *clip_rows.get(r, ())) for r, v in sorted(rows.items())], columns=columns
    )
    curve.attrs["per_clip_per_rater"] = per_clip_per_rater
    out["curve"] = curve
    return out


def _pair(design, given):
    conds = design["conditions"]
    if given:
        missing = [c for c in given if c not in conds]
        if missing:
            raise AnalysisError(f"--pair: condition {missing[0]!r} is not in the pilot ({', '.join(conds)})")
        if given[0] == given[1]:
            raise AnalysisError("--pair: two different conditions are needed")
        return tuple(given)
    # default: the pilot's closest pair, the hardest difference to detect
    pairs = [(abs(design["means"][x] - design["means"][y]), x, y) for i, x in enumerate(conds) for y in conds[i + 1 :]]
    _, x, y = min(pairs)
    return x, y


def build_parser():
    ap = cli.ArgumentParser(
        prog="python -m analysis.plan",
        description=__doc__.splitlines()[0],
        epilog="Covers the acr design (one clip rated 1-5 per trial); the pairwise and parallel designs have no "
        "planner yet.",
    )
    ap.add_argument("pilot", nargs="?", help="pilot ratings.csv (CONTRACTS.md §6); omit with --no-pilot")
    ap.add_argument(
        "--no-pilot", action="store_true", help="no pilot: take the variance components and design from the flags below"
    )
    ap.add_argument(
        "--pair",
        nargs=2,
        metavar=("A", "B"),
        help="the two conditions to tell apart (default: the pilot's closest pair)",
    )
    ap.add_argument(
        "--difference",
        type=cli.number(float, 0, 4, lo_open=True),
        help="mean rating difference to detect (default: the pilot's difference for the pair)",
    )
    ap.add_argument("--power", type=cli.number(float, 0.05, 0.999), default=0.8, help="target power (default 0.8)")
    ap.add_argument(
        "--alpha",
        type=cli.number(float, 0, 0.5, lo_open=True),
        default=0.05,
        help="family-wise error rate of Tukey HSD, as in the report (default 0.05)",
    )
    ap.add_argument(
        "--raters", type=cli.number(int, 2, MAX_RATERS), help="also give the power of a study with this many raters"
    )
    ap.add_argument(
        "--clips-per-condition",
        type=cli.number(int, 1, 10000),
        help="clips per condition (default: the pilot's; 30 with --no-pilot)",
    )
    ap.add_argument(
        "--clips-per-rater",
        type=cli.number(int, 1, 100000),
        help="test clips each rater rates (default: the pilot's median; all clips with --no-pilot)",
    )
    ap.add_argument(
        "--conditions", type=cli.number(int, 2, 20), default=3, help="number of conditions with --no-pilot (default 3)"
    )
    ap.add_argument("--sd-rater", type=cli.number(float, 0), help="rater SD (--no-pilot)")
    ap.add_argument("--sd-clip", type=cli.number(float, 0), help="clip SD (--no-pilot)")
    ap.add_argument("--sd-residual", type=cli.number(float, 0, lo_open=True), help="residual SD (--no-pilot)")
    ap.add_argument(
        "--threshold",
        type=cli.number(int, 1, 6),
        default=DEFAULT_THRESHOLD,
        help=f"the report's catch-trial exclusion threshold for the pilot (default {DEFAULT_THRESHOLD})",
    )
    ap.add_argument(
        "--n-sim",
        type=cli.number(int, 50, 1_000_000),
        default=1000,
        help="simulated studies per design size (default 1000)",
    )
    ap.add_argument("--seed", type=cli.number(int, 0, 2**32 - 1), default=0, help="simulation seed (default 0)")
    ap.add_argument("--out", default="plan", help="folder for power_curve.png and plan.json (default plan/)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap


def _design_from_flags(args):
    """(design, source, pair) for --no-pilot: everything from the command line."""
    need = [f for f in ("sd_rater", "sd_clip", "sd_residual", "difference") if getattr(args, f) is None]
    if need:
        raise AnalysisError(f"--no-pilot needs --{need[0].replace('_', '-')}")
    if args.pilot:
        raise AnalysisError(f"{args.pilot}: give a pilot file or --no-pilot, not both")
    conds = [f"C{i + 1}" for i in range(args.conditions)]
    C = args.clips_per_condition or 30
    design = {
        "conditions": conds,
        "means": {c: 0.0 for c in conds},
        "sd_rater": args.sd_rater,
        "sd_clip": args.sd_clip,
        "sd_residual": args.sd_residual,
        "clips_per_condition": C,
        "clips_per_rater": args.clips_per_rater or args.conditions * C,
        "n_raters": None,
    }
    source = "variance components from the command line"
    pair = _pair(design, args.pair) if args.pair else (conds[0], conds[1])
    return design, source, pair


def _design_from_pilot(args):
    """(design, source, pair) from a pilot's ratings, with the flags' overrides."""
    if not args.pilot:
        raise AnalysisError("give a pilot ratings file (or --no-pilot with the variance components)")
    df = load_ratings(args.pilot)
    test = only_test_rows(exclude_raters(df, args.threshold)[0])
    if test["condition"].nunique() < 2:
        raise AnalysisError(f"{args.pilot}: the pilot's kept test rows hold fewer than 2 conditions")
    try:  # the mixed model says why a pilot cannot be fitted (rating_models.random_effects_problem, an exact fit)
        design = pilot_design(test)
    except rating_models.ModelUndefined as exc:
        raise AnalysisError(f"{args.pilot}: the pilot cannot be fitted: {exc}") from None
    if args.clips_per_condition:
        design["clips_per_condition"] = args.clips_per_condition
    if args.clips_per_rater:
        design["clips_per_rater"] = args.clips_per_rater
    source = f"pilot {args.pilot} ({design['n_raters']} raters after the exclusion)"
    pair = _pair(design, args.pair)
    return design, source, pair


def _fewest_raters(power, target, max_raters):
    """The fewest raters whose `power(raters)` reaches `target` (None within `max_raters`): doubling until it is
    reached, then bisecting between the last two sizes."""
    lo_r, hi_r = 1, 2
    while power(hi_r) < target and hi_r < max_raters:
        lo_r, hi_r = hi_r, min(2 * hi_r, max_raters)
    if power(hi_r) < target:
        return None
    while hi_r - lo_r > 1:
        mid = (lo_r + hi_r) // 2
        if power(mid) >= target:
            hi_r = mid
        else:
            lo_r = mid
    return hi_r


def _clip_test(design, pair, target, n_sim, alpha, seed, check, max_raters, power, bar):
    """plan's clip_test: the decision on the clips' mean ratings, whose power more raters raise only up to what
    the clips' own spread allows (max_power: one study of the clips alone, every clip rated once and exactly)."""
    every_clip = len(design["conditions"]) * design["clips_per_condition"]
    alone = {**design, "sd_rater": 0.0, "sd_residual": 0.0, "clips_per_rater": every_clip}
    max_power = simulate_power(alone, pair, 1, n_sim, alpha, seed, progress=bar, unit="clip")[0]
    planned = _fewest_raters(power, target, max_raters) if max_power >= target else None
    return {
        "max_power": max_power,
        "planned_raters": planned,
        "power_at_check": power(int(check)) if check else None,
    }


def _clip_test_text(clip, target, clips, check) -> str:
    """The console's paragraph on plan's clip_test."""
    text = (
        "Counting the clips as the sample they are (Tukey HSD on the clips' mean ratings; the report's mixed model "
        "counts them too): "
    )
    if check:
        text += f"power {clip['power_at_check']:.3f} at {check} raters; "
    if clip["planned_raters"]:
        return text + f"power {target:g} needs {clip['planned_raters']} raters."
    return text + (
        f"power {target:g} is out of reach with {clips} clips per condition, however many raters (about "
        f"{clip['max_power']:.2f} with endless raters): more clips per condition are needed."
    )


def _main(argv):
    args = build_parser().parse_args(argv)
    cli.folder_to_write(args.out, "the plan's folder")  # before the simulation, not after it
    design, source, pair = (_design_from_flags if args.no_pilot else _design_from_pilot)(args)
    pilot_diff = design["means"][pair[1]] - design["means"][pair[0]]
    diff = args.difference if args.difference is not None else abs(pilot_diff)
    if not diff > 0:
        raise AnalysisError("the pilot shows no difference for the pair: give --difference")
    design = with_difference(design, pair, diff)
    every_clip = len(design["conditions"]) * design["clips_per_condition"]
    if args.clips_per_rater and args.clips_per_rater > every_clip:  # a pilot's own count is capped, a flag's said
        raise AnalysisError(
            f"--clips-per-rater {args.clips_per_rater}: the study has {every_clip} test clips "
            f"({len(design['conditions'])} conditions x {design['clips_per_condition']})"
        )
    design["clips_per_rater"] = min(design["clips_per_rater"], every_clip)
    res = plan(design, pair, args.power, args.n_sim, args.alpha, args.seed, args.raters, progress=not args.quiet)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AnalysisError(f"--out {out}: cannot create the folder ({exc.strerror or exc})") from None
    curve = res["curve"]
    title = f"{pair[1]} vs {pair[0]}, difference {diff:.2f}, Tukey HSD at alpha {args.alpha:g}"
    figures.power_curve(curve, args.power, out / "power_curve.png", title)
    doc = {
        "source": source,
        "pair": list(pair),
        "difference": diff,
        "alpha": args.alpha,
        "target_power": args.power,
        "n_sim": args.n_sim,
        "seed": args.seed,
        "test": "Tukey HSD over all conditions (the report's)",
        "design": {k: v for k, v in design.items()},
        **{k: v for k, v in res.items() if k != "curve"},
        "curve": curve.to_dict(orient="records"),
    }
    whole_files.write_whole(out / "plan.json", json.dumps(doc, indent=1))
    d = design
    print(
        f"Plan from {source}: {len(d['conditions'])} conditions x {d['clips_per_condition']} clips, each rater "
        f"rates {d['clips_per_rater']} clips; SD rater {d['sd_rater']:.3f}, clip {d['sd_clip']:.3f}, "
        f"residual {d['sd_residual']:.3f}."
    )
    print(
        f"Detecting {pair[1]} - {pair[0]} = {diff:.3f} with Tukey HSD at family-wise alpha {args.alpha:g} "
        f"({args.n_sim} simulated studies per size):\n"
    )
    print(f"{'raters':>7}{'ratings/clip':>14}{'power':>8}{'95% MC interval':>20}")
    for r in curve.itertuples():
        print(f"{r.raters:>7}{r.ratings_per_clip:>14.1f}{r.power:>8.3f}{f'[{r.low:.3f}, {r.high:.3f}]':>20}")
    print()
    if res["planned_raters"]:
        r = res["planned_raters"]
        print(
            f"Power {args.power:g} needs {r} raters in total ({r * curve.attrs['per_clip_per_rater']:.1f} ratings "
            f"per clip); estimated power there {res['planned_power']:.3f}."
        )
        print(
            f"False-positive rate of the same decision at that size when the difference is 0: "
            f"{res['false_positive_rate']:.3f} (nominal {args.alpha:g})."
        )
    else:
        print(
            f"Power {args.power:g} is not reached with up to {MAX_RATERS} raters: more clips per condition are "
            "needed (clip variation does not shrink with more raters)."
        )
    for r, p in res["power_at"].items():
        print(f"A study with {r} raters has power {p:.3f}.")
    check = res["planned_raters"] or args.raters
    print(_clip_test_text(res["clip_test"], args.power, design["clips_per_condition"], check))
    print(f"\nPower curve: {out / 'power_curve.png'}; table: {out / 'plan.json'}")
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
