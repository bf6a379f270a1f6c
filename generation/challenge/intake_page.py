"""The intake's pages: one per team (its verdict and every problem, to send to the team) and the challenge's table of
teams. Self-contained HTML: no script, no file from elsewhere, readable on a phone; every value escaped."""

from __future__ import annotations

import html
import time
from urllib.parse import quote

from moglow_eval.core.cli import version

STYLE = """
body { font: 16px/1.45 system-ui, sans-serif; margin: 0 auto; max-width: 60rem; padding: 1rem; color: #222; }
table { border-collapse: collapse; width: 100%; display: block; overflow-x: auto; }
th, td { text-align: left; padding: .3rem .5rem; border-bottom: 1px solid #ddd; vertical-align: top; }
th { background: #f3f3f3; }
.accepted { color: #17622b; font-weight: 600; }
.refused, .unusable { color: #a01818; font-weight: 600; }
code { font-size: 90%; overflow-wrap: anywhere; }
td:first-child { min-width: 8rem; }
footer { margin-top: 2rem; color: #666; font-size: 90%; }
"""


def _page(title: str, body: list[str]) -> str:
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    return "\n".join(
        [
            "<!doctype html>",
            '<html lang="en"><head><meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>",
            *body,
            f"<footer>Checked by moglow-eval {html.escape(version())} on {stamp}.</footer>",
            "</body></html>",
        ]
    )


def _rules_text(rules) -> str:
    samples = f"{rules.samples} samples per item" if rules.samples > 1 else "one file per item"
    if rules.samples > 1 and rules.or_one:
        samples += " (or one file per item from a deterministic system)"
    return (
        f"The rules checked: every test item, and nothing else, {samples}, all in one format the study reader takes; "
        f"{rules.fps:g} fps and the length of the item's speech within one frame; finite numbers and every frame "
        f"valid; a body of a person's height, no joint faster than {rules.max_speed:g} m/s, and (joint positions) no "
        f"bone changing its length by more than {100 * rules.max_bone_change:g}%."
    )


def team_page(row: dict, problems: list[dict], rules) -> str:
    """A team's page: its verdict with its counts, the rules, and one row per problem."""
    team, verdict = html.escape(row["team"]), row["verdict"]
    body = [
        f"<h1>Submission of {team}: <span class={verdict}>{verdict}</span></h1>",
        f"<p>{row['files']} files for {row['items_given']} of {row['items']} test items; "
        f"{row['problems']} problem{'s' if row['problems'] != 1 else ''}.</p>",
        f"<p>{html.escape(_rules_text(rules))}</p>",
    ]
    if problems:
        body.append("<table><thead><tr><th>file</th><th>check</th><th>what is wrong, and what to do</th></tr></thead>"
                    "<tbody>")  # fmt: skip
        body += [
            f"<tr><td><code>{html.escape(p['file'])}</code></td><td>{html.escape(p['check'])}</td>"
            f"<td>{html.escape(p['problem'])}</td></tr>"
            for p in problems
        ]
        body.append("</tbody></table>")
    else:
        body.append("<p>Every file passed every check.</p>")
    return _page(f"Intake: {row['team']}", body)


def challenge_page(rows: list[dict], rules) -> str:
    """The challenge's table: one row per team, linking its page."""
    body = [
        "<h1>Submissions</h1>",
        f"<p>{html.escape(_rules_text(rules))}</p>",
        "<table><thead><tr><th>team</th><th>verdict</th><th>items given</th><th>files</th><th>problems</th>"
        "<th>format</th></tr></thead><tbody>",
    ]
    for r in rows:
        team = html.escape(r["team"])
        link = (
            f'<a href="{html.escape(quote(r["team"]), quote=True)}/intake.html">{team}</a>'
            if r["verdict"] != "unusable"
            else team
        )
        body.append(
            f"<tr><td>{link}</td><td class={r['verdict']}>{r['verdict']}</td><td>{r['items_given']} of {r['items']}"
            f"</td><td>{r['files']}</td><td>{r['problems']}</td><td>{html.escape(r['format'])}</td></tr>"
        )
    body.append("</tbody></table>")
    return _page("Submissions", body)
