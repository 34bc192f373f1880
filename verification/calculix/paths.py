"""Load-deflection paths as lists of (W, P): the extremes of a path that rises, falls and rises
again, each read as the vertex of the parabola through the extreme point and its neighbours."""


def vertex(pts, i):
    """The vertex (W, P) of the parabola through the points i - 1, i, i + 1."""
    (x0, y0), (x1, y1), (x2, y2) = pts[i - 1], pts[i], pts[i + 1]
    d = (x0 - x1) * (x0 - x2) * (x1 - x2)
    a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / d
    b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / d
    c = y1 - a * x1 * x1 - b * x1
    return -b / (2 * a), c - b * b / (4 * a)


def extreme_points(pts):
    """(i_max, i_min): the first point before the load falls and the first after it where it
    rises again; None where absent."""
    ps = [p for _, p in pts]
    i_max = next((i for i in range(1, len(ps) - 1) if ps[i + 1] < ps[i]), None)
    if i_max is None:
        return None, None
    i_min = next((i for i in range(i_max, len(ps) - 1) if ps[i + 1] > ps[i]), None)
    return i_max, i_min


def extrema(pts):
    """(limit (W, P), minimum (W, P)) of a rising-falling-rising path, or None where absent."""
    i_max, i_min = extreme_points(pts)
    if i_max is None:
        return None, None
    return vertex(pts, i_max), (vertex(pts, i_min) if i_min is not None else None)
