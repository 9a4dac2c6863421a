"""The walk along one line of the model choice's grid search (facette.fit._li_model._profile_lobe):
which points of a sorted line of σ or n_i are solved and scored, and in what order.

    line_search(points, known, cost, how) -> {point: cost}
"""

__all__ = ["line_search"]


def line_search(points, known, cost, how):
    """{point: cost} of the points of a line (sorted) that a search evaluated (`known` given):
    "all" every point; "coarse-to-fine" every other point, then the neighbours of the best;
    "downhill" from the known point (else the middle) to its neighbours, on towards the lower
    one until a point is lower than both of its neighbours."""
    got = dict(known)

    def at(i):
        if points[i] not in got:
            got[points[i]] = cost(points[i])
        return got[points[i]]

    if how == "all":
        for i in range(len(points)):
            at(i)
        return got
    if how == "coarse-to-fine":
        for i in range(0, len(points), 2):
            at(i)
        if len(points) % 2 == 0:
            at(len(points) - 1)
    else:
        at(points.index(next(iter(known))) if known else len(points) // 2)
    while True:          # the best so far: its neighbours evaluated, moved to while one is lower
        i = points.index(min(got, key=got.get))
        todo = [j for j in (i - 1, i + 1) if 0 <= j < len(points) and points[j] not in got]
        if not todo:
            return got
        for j in todo:
            at(j)
