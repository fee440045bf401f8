"""Where a point lies relative to a world's closed surface: inside or out (its winding number) and
how deep (its distance to the nearest surface triangle). Used to report how deep a pad's edge lies
inside the object (``pad_edge_contact.evaluate_edge_points``), where a contact's plane depth alone
can read millimetres for a point beside the object that lies behind the extended plane of a face.
"""

import warp as wp

from .pad_edge_search import closest_point_barycentric

#: 1 / (4 pi): a triangle's solid angle (sr) as a share of the whole sphere.
INV_4PI = 0.07957747154594767


@wp.func
def triangle_solid_angle(a: wp.vec3, b: wp.vec3, c: wp.vec3):
    """Signed solid angle (sr) of triangle abc seen from the origin, positive where the origin
    lies behind it (its normal (b - a) x (c - a) points away): Van Oosterom and Strackee (1983)."""
    la = wp.length(a)
    lb = wp.length(b)
    lc = wp.length(c)
    num = wp.dot(a, wp.cross(b, c))
    den = la * lb * lc + wp.dot(a, b) * lc + wp.dot(a, c) * lb + wp.dot(b, c) * la
    return 2.0 * wp.atan2(num, den)


@wp.func
def winding_and_distance(x: wp.array(dtype=wp.vec3), triangles: wp.array(dtype=wp.vec3i), first: int, last: int,
                         p: wp.vec3):
    """(winding number, distance (m) to the nearest triangle) of p for ``triangles[first:last]``
    (a closed surface, outward by the right-hand rule, nodes at ``x``): the winding number is 1
    inside, 0 outside. Cost: one pass over the triangles."""
    solid = float(0.0)
    nearest = float(1.0e30)
    for t in range(first, last):
        ids = triangles[t]
        a = x[ids[0]]
        b = x[ids[1]]
        c = x[ids[2]]
        solid += triangle_solid_angle(a - p, b - p, c - p)
        bary = closest_point_barycentric(a, b, c, p)
        nearest = wp.min(nearest, wp.length(bary[0] * a + bary[1] * b + bary[2] * c - p))
    return solid * INV_4PI, nearest


@wp.func
def depth_inside_surface(x: wp.array(dtype=wp.vec3), triangles: wp.array(dtype=wp.vec3i), first: int, last: int,
                         p: wp.vec3):
    """Distance (m) from p to the nearest of ``triangles[first:last]`` where p lies inside that
    closed surface (winding number > 1/2), else 0 (``winding_and_distance``)."""
    winding, nearest = winding_and_distance(x, triangles, first, last, p)
    if winding > 0.5:
        return nearest
    return 0.0
