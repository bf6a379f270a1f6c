"""One-way ANOVA in exact rational arithmetic: the reference for NIST StRD SmLs07-09.

Those sets carry 13-15 constant leading digits (1000000000000.4), which float64 cannot even hold, so no
float algorithm can reach their certified values. Ratings never look like that, so this path lives with the
tests: it checks that the product's ANOVA table (analysis.stats.anova.anova_table) is right given exact sums.
"""

from fractions import Fraction

import pandas as pd

from analysis.stats import anova as stats


def one_way_anova_exact(df, dv, between):
    codes, levels = pd.factorize(df[between], sort=True)
    k = len(levels)
    s, s2, n = [Fraction(0)] * k, [Fraction(0)] * k, [0] * k
    for v, g in zip(df[dv], codes):
        q = Fraction(v)
        s[g] += q
        s2[g] += q * q
        n[g] += 1
    total, big_n = sum(s), sum(n)
    ss_within = sum(s2[g] - s[g] * s[g] / n[g] for g in range(k))
    ss_between = sum(s[g] * s[g] / n[g] for g in range(k)) - total * total / big_n
    return stats.anova_table(big_n, k, ss_between, ss_within)
