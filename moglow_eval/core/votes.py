"""What a pairwise vote is, shared by the app that stores it and the analysis that reads it (CONTRACTS §8).

A vote here is a 5-level preference between clip A and clip B (CONTRACTS §8: +2 = A clearly, 0 = none, -2 = B
clearly) with the reasons a rater ticked and an optional free text. The GENEA leaderboard (Nagy et al. 2025,
arXiv:2511.01233) writes the same vote as one row of a "battle" file: a winner (`model_a`, `model_b` or `tie`),
whether the preference was strong, the ticked reasons as a JSON list and the free text JSON-quoted. The app can
write that format and `analysis.import_votes` reads it, so the column names and the level mapping live here once.
"""

import json

# The realism reasons GENEA's leaderboard asks for with every vote: (id in its files, label a rater sees).
# The last one is its "other" box; our free-text field plays that part, so the app's default list is the first four.
REALISM_REASONS = (
    ("UnrealisticMotion", "Unrealistic motion"),
    ("MotionSmoothness", "Smoothness of the motion"),
    ("RecognisableGestures", "Recognisable gestures"),
    ("AmountIntensityOfMotion", "Amount and intensity of motion"),
)
OTHER_REASON = "MotionOther"  # the leaderboard's id for "other, see the free text"
REASON_ID_MAX = 40  # a reason id is a short identifier ([A-Za-z][A-Za-z0-9_]*), as the leaderboard's are
FREE_TEXT_MAX = 300  # characters of free text kept with a vote; a longer text is refused, never cut

# One row of a leaderboard battle file, in its column order.
BATTLE_COLUMNS = ("user", "input_code", "model_a", "model_b", "winner", "is_strong", "juiceOptions", "juiceOtherReason")
WINNERS = ("model_a", "model_b", "tie")


def preference_to_battle(preference: int) -> tuple[str, str]:
    """A −2..2 preference as the leaderboard's (winner, is_strong); a tie's strength is written empty."""
    if preference == 0:
        return "tie", ""
    return ("model_a" if preference > 0 else "model_b"), ("True" if abs(preference) == 2 else "False")


def battle_to_preference(winner: str, is_strong: str) -> int:
    """The leaderboard's (winner, is_strong) as a −2..2 preference for model_a; raises ValueError on other values."""
    if winner == "tie":
        return 0
    if winner not in WINNERS:
        raise ValueError(f"winner is {winner!r}, not one of {', '.join(WINNERS)}")
    strong = {"true": 2, "false": 1}.get(str(is_strong).strip().lower())
    if strong is None:
        raise ValueError(f"is_strong is {is_strong!r}, not True or False")
    return strong if winner == "model_a" else -strong


# The reasons' columns of pairs.csv (CONTRACTS §8): the ticked ids joined by REASON_SEPARATOR, and the free text.
REASONS_COLUMN = "reasons"
REASON_TEXT_COLUMN = "reason_text"
REASON_SEPARATOR = ";"

# The leaderboard's speech-mismatch study names the motion made for other speech as the system's name and this.
MISMATCH_SUFFIX = "_Mismatched"


# ------------------------------------------------------------------------------ the battle format's rows
def battle_row(user, input_code, model_a, model_b, preference: int, reasons, text: str) -> dict:
    """One battle row from a vote: `reasons` the ticked ids in order, `text` the free text ("" for none)."""
    winner, strong = preference_to_battle(int(preference))
    ids = list(reasons)
    if text and OTHER_REASON not in ids:
        ids.append(OTHER_REASON)  # the leaderboard's free text belongs to its "other" box
    return {
        "user": user,
        "input_code": input_code,
        "model_a": model_a,
        "model_b": model_b,
        "winner": winner,
        "is_strong": strong,
        "juiceOptions": json.dumps(ids, separators=(",", ":")) if ids else "{}",
        "juiceOtherReason": json.dumps(text) if text else "",
    }


def battles_from_pairs(rows):
    """Battle rows from pairs.csv rows (dicts as the export writes them): the test votes, in order."""
    for r in rows:
        if r["role"] != "test":
            continue
        reasons = [x for x in (r.get("reasons") or "").split(";") if x]
        yield battle_row(
            r["rater_id"],
            r["item"],
            r["condition_a"],
            r["condition_b"],
            r["preference"],
            reasons,
            r.get("reason_text") or "",
        )
