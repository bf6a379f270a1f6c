"""A simulated crowd: raters that use the public API exactly as the page does (`python -m rating_app simulate`).

It answers whatever design the server runs (the session reply names it, CONTRACTS §8). Three parts:
- `raters`: the rater model: each clip's quality (from metrics.csv beside the manifest, or per condition) and
  the answer an attentive or careless rater gives in each design;
- `client`: one rater's session through the HTTP API, fetching and waiting as the page does;
- `crowd`: many raters in a thread pool, and the summary of what was submitted and acknowledged.
"""

from .crowd import run_simulation, shortfall, write_summary
from .raters import parse_quality

__all__ = ["parse_quality", "run_simulation", "shortfall", "write_summary"]
