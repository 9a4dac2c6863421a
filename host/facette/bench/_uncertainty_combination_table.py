"""`facette bench uncertainty --combination`'s table: the rank combination (bench._uncertainty_combination)
fitted on the renders, its Spearman per case beside the band's, each group's mean; then the DiLiGenT bound."""
import numpy as np
from scipy.stats import spearmanr

from facette.bench._uncertainty_combination import COMBINED, fit_rank_model, leave_one_out, rank_score

__all__ = ["combination_table"]


def combination_table(rendered, real):
    """Print the table for the render Tallies `rendered` (fitted on) and the DiLiGenT Tally `real` (scored only)."""
    train = [(m, e) for t in rendered for _, m, e in t.cases]
    if not train:
        print("combination: no render cases kept (run with the renders)")
        return
    coef = fit_rank_model(train)
    print("combination of ranks fitted on the renders only: " +
          ", ".join(f"{k} {c:+.3f}" for k, c in zip(COMBINED + ("constant",), coef)), flush=True)
    print(f"{'case':40s} | band rho | combination rho")
    for tally in list(rendered) + [real]:
        rows = [(n, t[0], float(spearmanr(rank_score(m, coef), e).statistic))
                for (n, m, e), t in zip(tally.cases, tally.after)]
        for name, band, comb in rows:
            print(f"{name:40s} |    {band:5.2f} |           {comb:5.2f}", flush=True)
        if rows:
            print(f"{'mean over ' + tally.name:40s} |    {np.mean([r[1] for r in rows]):5.2f} |           "
                  f"{np.mean([r[2] for r in rows]):5.2f}", flush=True)
    objects = [(m, e) for _, m, e in real.cases]
    if len(objects) > 2:
        loo = leave_one_out(objects)
        own = [float(spearmanr(rank_score(m, fit_rank_model([(m, e)])), e).statistic) for m, e in objects]
        print("bound (never used for the map): fitted on the other DiLiGenT objects, mean "
              f"{np.mean(loo):.2f} (" + " ".join(f"{x:.2f}" for x in loo) + "); fitted on each object itself, mean "
              f"{np.mean(own):.2f} (" + " ".join(f"{x:.2f}" for x in own) + ")", flush=True)
