"""When the Bradley-Terry-Davidson fit has no maximum likelihood: separated votes and a tie parameter the data
cannot estimate (one system that won every vote once gave a "converged" fit with a tie parameter in the 100,000s).

- **Separation.** Draw an arrow from i to j whenever i beat or tied j in some vote. Conditions that reach each
  other along arrows form a component; between two components every vote went one way, so no finite difference
  of strengths fits them best (the ridge alone holds them apart). With more than one component the likelihood has
  no maximum, and the report says which conditions won or lost every vote (elo_ranks.unbounded).
- **The tie parameter.** A vote between components is certain in the limit whatever ν is, so only the votes
  within components tell ν. Where they are all ties, ν runs off to infinity and drags the strengths with it; the
  strengths are then fitted with ν fixed at NU_FIXED (a tie between equals as likely as a win), and the report
  gives ν as not estimable. Ties then still pull the conditions they join to one strength, so conditions the data
  treats alike come out alike and share a group.
"""

import numpy as np

NU_FIXED = 1.0


def components(total, pairs, k: int) -> list[list[int]]:
    """The strongly connected components (condition indices, in order) of the beat-or-tied graph of pair counts
    `total` [P, 3] (wins of the first, wins of the second, ties) over `pairs` [P, 2]."""
    reach = np.eye(k, dtype=bool)
    for (i, j), (wi, wj, t) in zip(np.asarray(pairs), np.asarray(total)):
        reach[i, j] |= bool(wi + t)
        reach[j, i] |= bool(wj + t)
    for m in range(k):  # Warshall: the transitive closure
        reach |= reach[:, m : m + 1] & reach[m : m + 1, :]
    both = reach & reach.T
    out, seen = [], set()
    for i in range(k):
        if i not in seen:
            comp = [j for j in range(k) if both[i, j]]
            seen.update(comp)
            out.append(comp)
    return out


def check(total, pairs, k: int) -> dict:
    """{"separated": more than one component, "nu_estimable": False where the votes have ties but every vote
    within a component is one}."""
    comps = components(total, pairs, k)
    where = np.zeros(k, int)
    for n, comp in enumerate(comps):
        where[comp] = n
    total, pairs = np.asarray(total, float), np.asarray(pairs, int)
    within = where[pairs[:, 0]] == where[pairs[:, 1]] if len(pairs) else np.zeros(0, bool)
    decisive = float(total[within, :2].sum()) if len(pairs) else 0.0
    ties = float(total[:, 2].sum()) if len(pairs) else 0.0
    return {"separated": len(comps) > 1, "nu_estimable": not ties or decisive > 0}
