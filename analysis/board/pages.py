"""A board's pages, written from a release's data (release.json, analysis.board.release): the results, a page per
task and per system, the data release, and the page a challenge shows before it publishes.

Self-contained HTML: no script at all, the style inline, no file from elsewhere; every value escaped; readable on a
phone (the viewport set, wide tables scroll inside their own box, videos as wide as the screen)."""

from __future__ import annotations

import html
import math

STYLE = """
*, *::before, *::after { box-sizing: border-box; }
body { font: 16px/1.45 system-ui, sans-serif; margin: 0 auto; max-width: 60rem; padding: 1rem; color: #222;
  overflow-wrap: anywhere; }
nav { display: flex; flex-wrap: wrap; gap: .25rem 1.25rem; margin-bottom: 1rem; }
.scroll { overflow-x: auto; max-width: 100%; }
table { border-collapse: collapse; min-width: 100%; }
th, td { text-align: left; padding: .3rem .5rem; border-bottom: 1px solid #ddd; white-space: nowrap; }
th { background: #f3f3f3; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; }
.videos { display: flex; flex-wrap: wrap; gap: 1rem; }
figure { margin: 0; flex: 1 1 16rem; max-width: 24rem; }
video { width: 100%; height: auto; background: #000; display: block; }
.note { color: #555; }
.methods { background: #f7f7f7; padding: .75rem; border-left: 3px solid #bbb; }
footer { margin-top: 2rem; color: #666; font-size: 90%; border-top: 1px solid #ddd; padding-top: .5rem; }
"""


def esc(text) -> str:
    return html.escape(str(text), quote=True)


def document(title: str, nav: list[tuple[str, str]], body: list[str], footer: str) -> str:
    """A whole page: `nav` is [(href, label)], `footer` the version and date line."""
    links = " ".join(f'<a href="{esc(href)}">{esc(label)}</a>' for href, label in nav)
    return "\n".join(
        [
            "<!doctype html>",
            '<html lang="en"><head><meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            f"<title>{esc(title)}</title><style>{STYLE}</style></head><body>",
            f"<nav>{links}</nav>",
            *body,
            f"<footer>{esc(footer)}</footer>",
            "</body></html>\n",
        ]
    )


def footer(release: dict) -> str:
    """Every page's last line: the board, its release and date, and the tool's version."""
    return (
        f"{release['title']} · release {release['release']} of {release['date']} · made with moglow-eval "
        f"{release['tool_version']}"
    )


def digits(task: dict) -> int:
    """Decimals a task's scores are shown with: none on the Elo scale, two on a five-point one."""
    top = max((abs(r["score"]) for r in task["systems"] if r["score"] is not None), default=0.0)
    return 0 if top >= 100 else 1 if top >= 10 else 2


def number(x, places: int) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{x:.{places}f}"


def interval(row: dict, places: int) -> str:
    return f"[{number(row['low'], places)}, {number(row['high'], places)}]"


def rank_text(row: dict) -> str:
    """A rank interval as a reader reads it: "2", or "1–3" where the data do not order the system further."""
    lo, hi = row["rank_low"], row["rank_high"]
    return f"{lo}" if lo == hi else f"{lo}–{hi}"


def table(head: list[tuple[str, bool]], rows: list[list[str]]) -> str:
    """A table that scrolls inside its own box on a narrow screen; `head` is [(heading, numeric)], cells are HTML."""
    num = [n for _, n in head]
    th = "".join(f'<th{" class=num" if n else ""} scope="col">{esc(h)}</th>' for h, n in head)
    body = "".join(
        "<tr>" + "".join(f"<td{' class=num' if n else ''}>{c}</td>" for c, n in zip(row, num)) + "</tr>" for row in rows
    )
    return f'<div class="scroll"><table><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table></div>'


def standings(task: dict, root: str, full: bool) -> str:
    """A task's table, best first: rank interval, system (linking its page), score and interval, and with `full`
    the group and the number of votes or ratings; `root` leads from the page to the release's folder."""
    places = digits(task)
    head = [("rank", False), ("system", False), (task["score"], True), ("95% interval", True)]
    head += [("group", True), (task["count"], True)] if full else []
    rows = []
    for r in task["systems"]:
        link = f'<a href="{esc(root)}systems/{esc(r["system"])}.html">{esc(r["system"])}</a>'
        row = [rank_text(r), link, number(r["score"], places), interval(r, places)]
        rows.append(row + ([str(r["group"]), str(r["n"])] if full else []))
    return table(head, rows)


def release_nav(root: str, top: str) -> list[tuple[str, str]]:
    return [(f"{root}index.html", "Results"), (f"{root}data.html", "Data"), (f"{top}index.html#releases", "Releases")]


def releases_list(releases: list[dict], prefix: str) -> str:
    """Every release of the board, newest first, each linking its own pages (which never change)."""
    items = [
        f'<li><a href="{esc(prefix)}releases/{r["release"]}/index.html">Release {r["release"]}</a>, {esc(r["date"])}'
        f"{' (this one)' if k == 0 else ''}</li>"
        for k, r in enumerate(sorted(releases, key=lambda r: -r["release"]))
    ]
    return f'<h2 id="releases">Releases</h2><ul>{"".join(items)}</ul>'


def results_page(release: dict, root: str, top: str, releases: list[dict] | None = None) -> str:
    """The results of a release: per task its table and a link to its page. At the board's top (`releases` given)
    it also lists every release; inside a release it links back to that list."""
    body = [
        f"<h1>{esc(release['title'])}</h1>",
        f"<p>Release {release['release']}, published {esc(release['date'])}. Per task, each system's score with its "
        "95% interval and its rank interval: the ranks the data allow it (a system ranks above another only where the "
        "task's statistics tell them apart).</p>",
    ]
    for task in release["tasks"]:
        name = esc(task["task"])
        body += [
            f'<h2 id="task-{name}">{name}</h2>',
            standings(task, root, full=False),
            f'<p><a href="{esc(root)}tasks/{name}.html">{name}: the whole table, its methods and its data</a></p>',
        ]
    if releases is not None:
        body.append(releases_list(releases, ""))
    return document(release["title"], release_nav(root, top), body, footer(release))


def files_table(files: list[dict], root: str) -> str:
    rows = [
        [f'<a href="{esc(root)}{esc(f["path"])}">{esc(f["path"].rsplit("/", 1)[-1])}</a>', esc(f["what"]),
         f"{f['bytes']:,}", f"<code>{f['sha256'][:16]}</code>"]
        for f in files
    ]  # fmt: skip
    return table([("file", False), ("what", False), ("bytes", True), ("SHA-256 (first 16)", False)], rows)


def task_page(release: dict, task: dict) -> str:
    """One task: its whole table, what the score and the ranks mean, the methods paragraph and its files."""
    name = esc(task["task"])
    body = [
        f"<h1>{name}</h1>",
        f"<p>{esc(task['about'])}</p><p class=note>rank: the ranks the data allow the system; group: systems whose "
        f"rank intervals overlap share one; {esc(task['count'])}: the answers the system received.</p>",
        standings(task, "../", full=True),
        "<h2>Methods</h2>",
        f'<p class="methods">{esc(task["methods"])}</p>',
        "<h2>Data</h2>",
        files_table(task["files"], "../"),
    ]
    return document(f"{release['title']}: {task['task']}", release_nav("../", "../../../"), body, footer(release))


def system_page(release: dict, system: str) -> str:
    """One system: in each task it took part in, its score, interval, rank and count, and a few of its videos (the
    blinded clips the raters saw, with their items)."""
    body = [f"<h1>{esc(system)}</h1>"]
    for task in release["tasks"]:
        row = next((r for r in task["systems"] if r["system"] == system), None)
        if row is None:
            continue
        name, places = esc(task["task"]), digits(task)
        body += [
            f'<h2><a href="../tasks/{name}.html">{name}</a></h2>',
            f"<p>{esc(task['score'])} {number(row['score'], places)} {interval(row, places)}, rank {rank_text(row)} "
            f"of {len(task['systems'])} (group {row['group']}), from {row['n']} {esc(task['count'])}.</p>",
            '<div class="videos">',
        ]
        for v in task["videos"].get(system, []):
            body.append(
                f'<figure><video controls playsinline preload="metadata" src="../{esc(v["video"])}"></video>'
                f"<figcaption>item: {esc(v['item'])}</figcaption></figure>"
            )
        body.append("</div>")
    return document(f"{release['title']}: {system}", release_nav("../", "../../../"), body, footer(release))


def data_page(release: dict) -> str:
    """The data release: per task its export, its manifest, its report's stats.json and methods, and the board's
    own table as CSV and JSON, each with its size and SHA-256; and the release's own release.json."""
    body = [
        "<h1>Data</h1>",
        "<p>Everything the results were computed from, copied into this release: per task the raters' answers as the "
        "rating app exported them, the stimulus manifest (each clip's system and item), the report's statistics and "
        'methods, and the tables of these pages. <a href="release.json">release.json</a> holds this release\'s '
        "tables, files and videos in one file (its format: docs/CONTRACTS.md).</p>",
    ]
    for task in release["tasks"]:
        body += [f"<h2>{esc(task['task'])}</h2>", files_table(task["files"], "")]
    return document(f"{release['title']}: data", release_nav("", "../../"), body, footer(release))


def preview_page(board: dict) -> str:
    """A challenge's board before it publishes: its tasks and how each is rated and analysed, and the date; nothing
    of any system (no name, score or video)."""
    body = [
        f"<h1>{esc(board['title'])}</h1>",
        f"<p>The results are not published yet. This page, built on {esc(board['date'])}, shows the tasks and how "
        "each is evaluated; the scores, ranks, videos and data appear here when the results are published.</p>",
    ]
    for task in board["tasks"]:
        body += [f"<h2>{esc(task['task'])}</h2>", f'<p class="methods">{esc(task["methods"])}</p>']
    line = f"{board['title']} · not yet published · built {board['date']} with moglow-eval {board['tool_version']}"
    return document(board["title"], [("index.html", "Tasks")], body, line)
