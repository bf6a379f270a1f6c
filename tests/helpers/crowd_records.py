"""What a crowd's run leaves in each design, for the tests that check that no acknowledged answer is lost or
stored twice (tests/rating_app/test_app_load.py, test_outage.py)."""

from moglow_eval.core import study
from rating_app.designs.acr import iter_rows
from rating_app.designs.appropriateness import iter_fit_rows
from rating_app.designs.pairwise import iter_pair_rows
from rating_app.designs.parallel import iter_page_rows

# Per design: the acknowledged record's identity, the export's rows, acknowledged records per rater (2 test and 2
# catch trials; a parallel page acknowledges each of its clips: 2 x 3 test + 2 x 3 catch, a catch page being as large
# as a test page) and the balanced unit of a test row (None: the row is counted through another row of its unit).
# The load test runs every design of moglow_eval.core.study.DESIGNS, so a design missing here fails it
# (docs/ARCHITECTURE.md, "A test design").
DESIGNS = {
    "acr": (("rater_id", "clip_id", "rating"), iter_rows, 4, lambda r: r["clip_id"]),
    "pairwise": (
        ("rater_id", "clip_a", "clip_b", "preference"),
        iter_pair_rows,
        4,
        lambda r: (r["item"], *sorted((r["condition_a"], r["condition_b"]))),
    ),
    "appropriateness": (
        ("rater_id", "clip_a", "clip_b", "preference"),
        lambda s: iter_fit_rows(s, "mismatched_item"),
        4,
        lambda r: (r["item"], r["condition_a"]),
    ),
    "parallel": (
        ("rater_id", "page_id", "clip_id", "rating"),
        iter_page_rows,
        12,
        lambda r: r["item"] if r["condition"] == "NAT" else None,
    ),
    # dyadic and semantic: appropriateness's units and rows under their own mismatch column (CONTRACTS §8)
    **{
        name: (
            ("rater_id", "clip_a", "clip_b", "preference"),
            lambda s, column=study.MISMATCH_COLUMN[name]: iter_fit_rows(s, column),
            4,
            lambda r: (r["item"], r["condition_a"]),
        )
        for name in ("dyadic", "semantic")
    },
}
