"""What every test design (CONTRACTS §8) is to the app: one small interface, which each design implements.

A study's design decides what one trial shows and what its answer is. The composites (the API, the export, the
dashboard, the start-up, the simulated crowd) hold no design of their own: they ask the study's `Design` object
for its units, its trial payload, its answer, its storage, its export rows and its dashboard figures, so adding a
design never touches them (docs/ARCHITECTURE.md, "How to add ... A test design").

A design balances either clips (acr: a slot gets a clip, `Trial.clip_id`) or units (the others: a slot gets a
`Unit`, `Trial.unit`, whose clips are `TrialClip` rows labelled A, B, ...); `UnitDesign` (units.py) is the shared
implementation of the second kind. Units are derived from the manifest alone (the same on every worker and after
every restart), and named by a key that is stored with each trial, so coverage is counted per unit in the
database.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from moglow_eval.core import votes

MAX_PAGE = 8  # clips on one trial's page (labels A..H)
LABELS = "ABCDEFGH"


@dataclass(frozen=True)
class Unit:
    key: str  # stored in trials.unit
    role: str  # test | catch
    item: str
    clips: tuple[str, ...]  # clip ids (shuffled per trial when served)


class Design:
    """One test design. Class attributes name its facts; methods are its behaviour in each part of the app."""

    name = ""  # as moglow_eval.core.study.DESIGNS spells it: in the database, the API's "design" and the files
    answer_field = ""  # the JSON field that carries an answer (API, simulated crowd)
    answer_extra: tuple[str, ...] = ()  # further optional answer fields (pairwise: its reasons)
    answer_noun = "answer"  # what one answer is called in messages
    question = ""  # the page's default question
    export_file = ""  # the export's file name (/admin/export.csv)
    export_noun = ""  # what one export row is, for the export command's log line
    columns: tuple[str, ...] = ()  # the export's columns, in order
    several_clips = True  # a trial shows TrialClip rows (labelled A, B, ...) rather than one Trial.clip_id
    # The reasons asked with a vote (store/reasons.py): whether the design can take them, and its defaults.
    takes_reasons = False
    # A study that grows (store/rounds.py, operations/conditions.py): whether a new condition only adds units, so
    # that `add-condition` may begin a round (a parallel page, or a mismatched pair, would change instead).
    grows = False
    # Whether the study may pair adaptively and stop on a settled ranking (PAIRING, STOP_WHEN; pairing/active.py).
    ranks_conditions = False
    battles = False  # whether its export rows are votes between two systems, as the leaderboard's battles are
    default_reasons: tuple[tuple[str, str], ...] = ()
    default_reason_text = 0
    page = ""  # how the rater's page (static/study.js) shows a trial: "one" clip, a "pair" A/B, a "page" of clips
    # The dashboard's words (templates/admin.html): what the design is, what its units and answers are called.
    dashboard = {
        "note": "",  # after the design's name
        "units": "clips",  # test units, counted
        "answers": "answers",
        "per_condition": "condition",  # the per-condition table's heading: "Per ..."
        "mean": "mean",  # that table's mean column
        "per_unit": "clip",  # the per-unit table's heading: "Per ..."
        "unit_column": "unit",
    }

    def battle_rows(self, session):
        """The GENEA leaderboard's battle rows of this study's test votes (operations/battles.py), or None where the
        design's answers are not votes between two systems (`battles`)."""
        return votes.battles_from_pairs(self.export_rows(session)) if self.battles else None

    @property
    def page_template(self) -> str:
        """The design's parts of the rater's page (welcome, viewing rule, introductions): Jinja macros that
        templates/study.html imports."""
        return f"designs/{self.name}.html"

    # -------------------------------------------------------------------------------- units and assignment
    def serving_clips(self, clips) -> list:
        """The manifest's clips this design serves: by default all but the mismatched ones (those showing another
        item's motion), which only the appropriateness test uses."""
        return [c for c in clips if not c.motion_item]

    def build_units(self, clips) -> dict[str, Unit]:
        """{key: Unit} of the test and catch units; AppError when the manifest cannot make this design."""
        raise NotImplementedError

    def cover_keys(self, clips, units) -> list[str]:
        """What assignment balances (a db.Cover row each): test and catch clips or units."""
        raise NotImplementedError

    def pool(self, clips, units) -> tuple[int, int]:
        """(test units, catch units) that assignment draws from, for the catch-pool check (operations/health.py)."""
        raise NotImplementedError

    def plan(self, conn, rng: random.Random, cfg, clips, units) -> list:
        """[(kind, a clip id, a training group of clip ids, or None for a slot)] in presentation order for a new
        session; assign.StudyFull when no unit is short of its target."""
        raise NotImplementedError

    def assign(self, conn, rng: random.Random, rater_pk: int, kind: str, target: int, units, wait: bool):
        """The clip id or Unit for a test or catch slot now being served, or None when none is left."""
        raise NotImplementedError

    def is_full(self, conn, target: int, units) -> bool:
        """Every test clip or unit has its target of answers."""
        raise NotImplementedError

    # ------------------------------------------------------------------------------------------- a trial
    def required_ms(self, durations: list[int]) -> int:
        """How long the clips of one trial take to play to the end (before the viewing rule's tolerance)."""
        raise NotImplementedError

    def payload(self, clips: list[dict]) -> dict:
        """The design's part of a trial as sent to the page, from its clips as shown
        ({"clip_id", "label", "video_url"} each, in order)."""
        raise NotImplementedError

    # -------------------------------------------------------------------------------------------- answers
    def parse_answer(self, body: dict, shown) -> object:
        """The value of a rating-phase answer in `body` (the field is there); 400 when it is not one."""
        raise NotImplementedError

    def store(self, conn, trial, rater_pk: int, shown, value, watched_ms, now, flags: str) -> None:
        """Insert the answer, in the transaction that claimed the trial."""
        raise NotImplementedError

    def stored_answer(self, conn, trial_pk: int):
        """The answer stored for a trial (what a repeated answer is told), or None."""
        raise NotImplementedError

    # ---------------------------------------------------------------------------------- export, dashboard
    def export_rows(self, s):
        """The export's rows (dicts keyed by `columns`), in rater and trial order."""
        raise NotImplementedError

    def catch_answers(self, rows):
        """(rater_id, failed a catch trial) per answer of the export `rows`, by the design's catch rule in
        moglow_eval.core.study: what study.excluded_raters takes."""
        raise NotImplementedError

    def progress(self, s, target: int, units) -> dict:
        """The dashboard's figures: {"per_clip", "per_condition", and {rater_id: count} for "answers", "fails",
        "no_video", "partial_video"}."""
        raise NotImplementedError

    # --------------------------------------------------------------------------------- the simulated crowd
    def simulated_answer(self, rater, ids: list[str], shown):
        """(the answer a simulated rater (simulate.raters.Rater) gives to a trial showing `shown`, watched_ms)."""
        raise NotImplementedError

    def catch_failed(self, ids: list[str], conditions: list, value) -> bool:
        """Whether an answer to a catch trial fails it, by the design's rule in moglow_eval.core.study."""
        raise NotImplementedError

    def records(self, head: dict, ids: list[str], shown, value, role: str) -> list[dict]:
        """The acknowledged answer as the crowd's summary lists it; `head` holds rater_id, external_id, trial_id
        and careless."""
        raise NotImplementedError


def new_condition_row(condition, role) -> dict:
    """A dashboard row of one condition (or condition pair) before its counts; "_sum" becomes its "mean"."""
    return {"condition": condition, "role": role, "clips": 0, "ratings": 0, "target": 0, "_sum": 0}
