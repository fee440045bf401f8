"""Where a point lies relative to a world's closed surface: inside or out (its winding number) and
how deep (its distance to the nearest surface triangle). Used by the pad edge contact
(``pad_edge_contact.py``) for points whose contact plane alone cannot say: a point beside the
object, off a convex edge, lies behind the extended plane of a face it does not touch.
"""

import warp as wp

from .pad_edge_search import closest_point_barycentric

#: 1 / (4 pi): a triangle's solid angle (sr) as a share of the whole sphere.
INV_4PI = 0.07957747154594767


@wp.func
def triangle_solid_angle(a: wp.vec3, b: wp.vec3, c: wp.vec3):
    """Signed solid angle (sr) of triangle abc seen from the origin, positive where the origin
    lies behind it (its normal (b - a) x (c - a) points away): Van Oosterom and Strackee (1983).
    0 for a degenerate triangle (zero triple product)."""
    la = wp.length(a)
    lb = wp.length(b)
    lc = wp.length(c)
    num = wp.dot(a, wp.cross(b, c))
    den = la * lb * lc + wp.dot(a, b) * lc + wp.dot(a, c) * lb + wp.dot(b, c) * la
    return 2.0 * wp.atan2(num, den)


@wp.func
def winding_number(x: wp.array(dtype=wp.vec3), triangles: wp.array(dtype=wp.vec3i), first: int, last: int,
                   p: wp.vec3):
    """Winding number of ``triangles[first:last]`` (a closed surface, outward by the right-hand
    rule, nodes at ``x``) at p: 1 inside, 0 outside. Cost: one pass over the triangles."""
    solid = float(0.0)
    for t in range(first, last):
        ids = triangles[t]
        solid += triangle_solid_angle(x[ids[0]] - p, x[ids[1]] - p, x[ids[2]] - p)
    return solid * INV_4PI


@wp.func
def depth_inside_surface(x: wp.array(dtype=wp.vec3), triangles: wp.array(dtype=wp.vec3i), first: int, last: int,
                         p: wp.vec3):
    """Distance (m) from p to the nearest of ``triangles[first:last]`` where p lies inside that
    closed surface (``winding_number`` > 1/2), else 0. Degenerate (zero-area) triangles are left out
    of the distance (their closest point is undefined). Cost: one pass over the triangles, a second
    for a point inside."""
    if winding_number(x, triangles, first, last, p) <= 0.5:
        return 0.0
    nearest = float(1.0e30)
    for t in range(first, last):
        ids = triangles[t]
        a = x[ids[0]]
        b = x[ids[1]]
        c = x[ids[2]]
        if wp.length(wp.cross(b - a, c - a)) > 0.0:
            bary = closest_point_barycentric(a, b, c, p)
            nearest = wp.min(nearest, wp.length(bary[0] * a + bary[1] * b + bary[2] * c - p))
    return nearest
