"""The facts every part of a study agrees on (CONTRACTS.md §4, §6, §8), each defined once here.

The parts exchange files, not code, so these names are also what the files hold: a condition column reads
"NAT", a role column "catch", a clip id matches CLIP_ID.
"""

import collections
import re
import secrets

NATURAL = "NAT"  # the motion-capture condition: the reference every design compares against
GENERATED = ("MG", "FL")  # the paper's two generators, trained and sampled by `generation`
BUILTIN = (NATURAL, *GENERATED)  # what make_stimuli makes without --system
CATCH = "BAD"  # the early-training catch condition (paper §5)
RESERVED = (*BUILTIN, CATCH)  # names an imported system may not take

ROLES = ("test", "catch", "training")  # a clip's role in manifest.csv; "training" = familiarisation
RATED_ROLES = ("test", "catch")  # the roles that reach a ratings export

# A rating of a BAD clip at or above this, on the paper's 1-5 scale, fails the catch trial (paper §5.2).
CATCH_FAIL_AT = 3

# The test designs (CONTRACTS §8), as the database, the API and the files name them; each part implements them
# behind its own interface and lists them in its registry (rating_app.designs, analysis.designs).
DESIGNS = ("acr", "pairwise", "parallel", "appropriateness", "dyadic", "semantic")
# The designs that set a system's matched clip against its mismatched one (GENEA 2023's appropriateness, its
# interlocutor test, GENEA 2026's semantic alignment), and the export column that names what the mismatched motion was
# made for: another item's speech, another interlocutor, another utterance (CONTRACTS §8). The column tells the
# analysis which design a file holds.
MISMATCH_COLUMN = {
    "appropriateness": "mismatched_item",
    "dyadic": "mismatched_interlocutor",
    "semantic": "mismatched_utterance",
}
DEFAULT_DESIGN = "acr"  # the paper's design: a study, a database or a file that names none

# The test items each of the demo's studies with speech can make, from the first to the last: one person talking
# (generation.own_study.demo_study) and two people in conversation (generation.own_study.demo_dyad, which pairs the
# long takes of the actions data and finds thirty pairs at most). analysis.demo checks its --items against them before
# it replaces an earlier run; the two commands take them as their own --items bounds.
SPEECH_DEMO_ITEMS = (3, 60)
TWO_PERSON_DEMO_ITEMS = (3, 30)
# The designs whose demo study is two people in conversation (generation.own_study.demo_dyad builds it, analysis.demo
# asks for it); the demo's other designs with sound get one person talking (generation.own_study.demo_study).
TWO_PERSON_DEMO_DESIGNS = ("dyadic", "semantic")

# Clip ids are random, so a file or URL name tells a rater nothing about the condition (CONTRACTS §4).
CLIP_ID = re.compile(r"[a-z0-9]{12,64}")  # always fullmatch
CLIP_ID_LENGTH = 16  # what make_stimuli writes
CLIP_ID_ALPHABET = "abcdefghijklmnopqrstuvwxyz0123456789"

# Per-clip objective metrics in metrics.csv (CONTRACTS §4), in column order; generation.metrics.objective computes them.
METRIC_NAMES = ("foot_skating", "bone_length_std", "jerk", "control_error", "control_following", "acceleration")
METRIC_KEYS = ("clip_id", "condition", "role", "item")  # the columns of metrics.csv that are not metrics
# The locomotion metrics among them: a gesture study (speech, an SMPL-family or speech-gesture skeleton) writes them
# as nan, and says so in MEASURES_FILE.
LOCOMOTION_METRICS = ("foot_skating", "control_error", "control_following")
# The gesture measures a gesture study adds to metrics.csv, in column order (docs/metrics.md; generation.metrics.gesture
# computes them): the Fréchet gesture distance, BeatAlign, the Hellinger distances of each joint group's speed and
# acceleration histograms, diversity, and a two-person study's listener response.
JOINT_GROUPS = ("hands", "arms", "head")
HELLINGER_METRICS = tuple(f"hellinger_{kind}_{g}" for kind in ("speed", "accel") for g in JOINT_GROUPS)
GESTURE_METRIC_NAMES = ("fgd", "beat_align", *HELLINGER_METRICS, "diversity", "listener_response")
# Which way each measure is better, for the report's rank agreement with people: "lower", "higher", or "reference"
# (the closer to the reference condition's value, the better). A column not named here is read as "higher".
METRIC_DIRECTION = {
    "foot_skating": "lower",
    "bone_length_std": "lower",
    "jerk": "reference",
    "control_error": "lower",
    "control_following": "lower",
    "acceleration": "reference",
    "fgd": "lower",
    "beat_align": "higher",
    **{name: "lower" for name in HELLINGER_METRICS},
    "diversity": "reference",
    "listener_response": "reference",
}
# Beside metrics.csv in a study of your own motion (CONTRACTS §4): each measure's status and why, and a gesture
# study's per-condition values.
MEASURES_FILE = "measures.csv"
MEASURES_COLUMNS = ("measure", "status", "clips", "reason", "settings")
MEASURE_STATUS = ("measured", "partly", "skipped")
GESTURE_FILE = "gesture.csv"

# A study of your own motion writes its reference as NATURAL in the manifest (every design's catch and anchor
# rules key on it); the name the study file gave it travels beside the manifest in this file, as
# {"reference_name": NAME} (CONTRACTS §4), into the app's export as a column of that name (§6), and back into the
# report's tables and figures.
STUDY_NAMES_FILE = "study.json"
REFERENCE_NAME = "reference_name"
# A two-person study's study.json also gives the interlocutor's drawing colour, "#RRGGBB" (core.colours), so that
# the rater's page names the colour the videos show.
INTERLOCUTOR_COLOUR = "interlocutor_colour"
# A condition's name as a user gives it (an imported system, a study file's condition): short, and safe in a file
# name, a CSV cell, an HTML page and a figure label. Always fullmatch.
CONDITION_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,31}")
# A stochastic system's sample of an item (the manifest's `sample`, CONTRACTS §4): its file's name in the team's
# ITEM/ folder. Exported, never shown to a rater.
SAMPLE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


def condition_order(conditions):
    """The paper's order for tables and figures: NAT, MG, FL, then other systems in name order, BAD last."""
    conditions = list(dict.fromkeys(conditions))
    head = [c for c in BUILTIN if c in conditions]
    tail = sorted(c for c in conditions if c not in BUILTIN and c != CATCH)
    return head + tail + ([CATCH] if CATCH in conditions else [])


def new_clip_id(taken, forbidden=RESERVED):
    """A random CLIP_ID_LENGTH-character id, not in `taken` (which it joins), containing no name in `forbidden`
    (case-insensitively), so that no id spells out a condition."""
    forbidden = [f.lower() for f in forbidden]
    while True:
        cid = "".join(secrets.choice(CLIP_ID_ALPHABET) for _ in range(CLIP_ID_LENGTH))
        if cid not in taken and not any(f in cid for f in forbidden):
            taken.add(cid)
            return cid


# The catch rules of the three designs (CONTRACTS §6, §8). Written with & and |, they take scalars or whole
# pandas columns alike, so the app's export and the analysis apply literally the same rule.
def acr_catch_failed(rating):
    """An acr rating of a BAD clip fails the catch trial at CATCH_FAIL_AT or above."""
    return rating >= CATCH_FAIL_AT


def pair_catch_failed(condition_a, condition_b, preference):
    """A pairwise answer prefers the BAD clip at either level (preference > 0 favours A, < 0 favours B)."""
    return ((condition_a == CATCH) & (preference > 0)) | ((condition_b == CATCH) & (preference < 0))


def page_catch_failed(bad_rating, natural_rating):
    """A parallel page rates its BAD clip at or above its NAT clip."""
    return bad_rating >= natural_rating


# The rater exclusion (CONTRACTS §6, §8): a rater who fails this many catch trials, by the design's rule above, is
# excluded. Their answers are kept and exported (flagged `failed_catch`), and none of them enters a statistic: not
# the report's primary analysis, nor the app's ranking (the posterior behind active pairs, the stopping rule, the
# dashboard's "how far from settled"). Both parts call `excluded_raters`, so they exclude the same raters.
EXCLUDE_AT_FAILS = 1


def excluded(n_failed: int) -> bool:
    """Whether a rater who failed `n_failed` catch trials is excluded."""
    return n_failed >= EXCLUDE_AT_FAILS


def excluded_raters(catch_answers) -> list:
    """The raters excluded, sorted, from (rater, failed) for each catch answer (any other answer may come too,
    as failed False)."""
    fails = collections.Counter(rater for rater, failed in catch_answers if bool(failed))
    return sorted(rater for rater, n in fails.items() if excluded(n))
