"""What every report shares: the page around a design's sections, its tables, figures and p-values as text, and
stats.json's cleaning (numpy scalars to Python, NaN to null). Pure formatting: no statistics here.
"""

import base64
import html
import math
from pathlib import Path

import numpy as np
import pandas as pd


def clean(x):
    """numpy scalars -> Python; NaN/inf -> None (JSON has neither)."""
    if isinstance(x, dict):
        return {str(k): clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [clean(v) for v in x]
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        x = float(x)
        return x if math.isfinite(x) else None
    return x


def records(df):
    return df.to_dict(orient="records")


def count(n, noun):
    """`n` and the noun, plural unless n is 1: "1 rater", "2 raters"."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def was(n):
    """The verb for `n` things: "was" for one, "were" for any other number (none included)."""
    return "was" if n == 1 else "were"


def excluded_text(counts, reason):
    """The summary's sentence of the raters excluded: "N rater(s) REASON and was/were excluded"."""
    n = counts["n_raters_excluded"]
    return f"{count(n, 'rater')} {reason} and {was(n)} excluded"


def p_text(p, bound=False):
    """A p-value as text; `bound`: p is an upper bound (a Tukey tail beyond what can be computed), "< 2e-40"."""
    if p is None or not np.isfinite(p):
        return "n/a"
    if bound:
        return f"<{p:.0e}"
    if p == 0:  # a tail below the smallest double
        return "<1e-300"
    return f"{p:.2e}" if p < 1e-4 else f"{p:.4f}"


def p_equals(p):
    text = p_text(p)
    return f"p {text[0]} {text[1:]}" if text.startswith("<") else f"p = {text}"


def why_not(model):
    return model.get("skipped") or model.get("undefined") or model.get("error")


# ---------------------------------------------------------------------------------------------- report.html
CSS = """body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:980px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}h1{font-size:1.6em}h2{font-size:1.2em;margin-top:1.8em;
border-bottom:1px solid #ddd}table{border-collapse:collapse;margin:.6em 0;font-size:.88em}
td,th{border:1px solid #ddd;padding:3px 8px;text-align:right}th{background:#f5f5f5}td:first-child,
th:first-child{text-align:left}img{max-width:min(100%,780px)}.note{color:#555;font-size:.9em}.cols{display:flex;gap:2em;
flex-wrap:wrap}.warn{background:#fff4e0;border-left:4px solid #e69500;padding:.4em .8em}"""


def table(df, pcols=()):
    df = df.copy()
    for c in df.columns:
        if c in pcols:
            df[c] = df[c].map(lambda v: p_text(v))
        elif df[c].dtype.kind == "f":
            df[c] = df[c].map(lambda v: "" if not np.isfinite(v) else f"{v:.4f}")
    return df.to_html(border=0, escape=True, index=not isinstance(df.index, pd.RangeIndex))


def img(path):
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(Path(path).stem)}" src="data:image/png;base64,{data}">'


def mixed_html(m):
    if not m.get("fixed_effects"):
        return f"<p>Not fitted: {html.escape(str(why_not(m)))}</p>"
    fe = pd.DataFrame(
        {
            "estimate": m["fixed_effects"],
            "std. error": m["std_errors"],
            "df": m["df"],
            "95% low": m["ci_low"],
            "95% high": m["ci_high"],
            "p": m["p_values"],
        }
    )
    vc = pd.DataFrame({"variance": m["variance_components"]})
    warn = f"<p class=note>Fit warnings: {html.escape('; '.join(m['warnings']))}</p>" if m["warnings"] else ""
    return (
        f"<p>{html.escape(m['formula'])}, {html.escape(m['method'])}; reference level "
        f"<b>{html.escape(m['reference'])}</b>; converged: {m['converged']}.</p>"
        f"<div class=cols>{table(fe, ('p',))}{table(vc)}</div>{warn}"
        "<p class=note>t tests and intervals on Satterthwaite degrees of freedom (as lmerTest).</p>"
    )


def page(body) -> str:
    """The report.html document around its parts (a list of HTML strings), styled inline: it opens offline."""
    return (
        "<!doctype html><html lang=en><head><meta charset=utf-8><title>Perceptual test report</title>"
        f"<style>{CSS}</style></head><body>{''.join(body)}</body></html>"
    )
