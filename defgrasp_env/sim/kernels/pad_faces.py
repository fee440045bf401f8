"""Where a node meets a pad's collision box: the box's faces, the face a node meets it through in a
substep, and the node's depth behind that face.

Each node meets each box through one face per substep, chosen at the substep start by continuous
collision detection of the node's motion relative to the box (``contact_face``); the penalty then
pushes the node out through that face, or through a side face of that face's extent where the node
is nearer to it (while it is not past the opposite face), never through the opposite face
(``face_contact``), so a box that moves further
than its half thickness in a substep cannot push nodes out of its far side (the nearest face of a
deep node is the wrong one), and the depth is continuous where a node slides past the face's edge
(it jumped from 0 to the full depth there until 2026-12-07, which stalled Newton in violent
impacts: benchmarks/RESULTS.md, "the contact fuzz's cylinder at the default limits"). All in the
box's frame (m); the penalty and friction laws that use them are in ``contact.py``.
"""

import warp as wp

# forward only: nothing differentiates these functions, and adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.func
def box_penetration(local: wp.vec3, half: wp.vec3):
    """Penetration depth (m, > 0 inside) of a point given in box coordinates, and the outward
    normal (box frame) of the nearest face."""
    d0 = half[0] - wp.abs(local[0])
    d1 = half[1] - wp.abs(local[1])
    d2 = half[2] - wp.abs(local[2])
    depth = d0
    n = wp.vec3(wp.sign(local[0]), 0.0, 0.0)
    if d1 < depth:
        depth = d1
        n = wp.vec3(0.0, wp.sign(local[1]), 0.0)
    if d2 < depth:
        depth = d2
        n = wp.vec3(0.0, 0.0, wp.sign(local[2]))
    return depth, n


@wp.func
def axis_normal(axis: int, sign: float):
    n = wp.vec3(0.0)
    n[axis] = sign
    return n


@wp.func
def contact_face(start: wp.vec3, guess: wp.vec3, half: wp.vec3):
    """Outward normal (box frame) of the face through which a node meets the box in a substep.

    ``start``: the node at the substep start in the box's start frame; ``guess``: its predicted
    end position in the box's end frame (both m). A node inside at the start (shallow, as every
    returned state is) keeps its nearest face. Otherwise the segment start -> guess, the node's
    motion relative to the box, is clipped against the three slabs (continuous collision
    detection): the slab entered last is the face it crosses first. A node the segment does not
    bring into the box gets the face of its largest separation (the side it is on)."""
    if wp.abs(start[0]) < half[0] and wp.abs(start[1]) < half[1] and wp.abs(start[2]) < half[2]:
        depth, n = box_penetration(start, half)
        return n
    d = guess - start
    t_enter = float(0.0)
    t_exit = float(1.0)
    entry = int(-1)
    hit = int(1)
    best = int(0)
    separation = float(-1.0e30)
    for j in range(3):
        gap = wp.abs(start[j]) - half[j]
        if gap > separation:
            separation = gap
            best = j
        if wp.abs(d[j]) < 1.0e-12:
            if gap >= 0.0:
                hit = 0
        else:
            t0 = (-half[j] - start[j]) / d[j]
            t1 = (half[j] - start[j]) / d[j]
            if t0 > t1:
                tmp = t0
                t0 = t1
                t1 = tmp
            if t0 > t_enter:
                t_enter = t0
                entry = j
            t_exit = wp.min(t_exit, t1)
    if hit == 1 and entry >= 0 and t_enter <= t_exit:
        best = entry
    return axis_normal(best, wp.sign(start[best]))


@wp.func
def face_contact(local: wp.vec3, half: wp.vec3, n: wp.vec3):
    """(depth, outward normal), box frame, of a point behind the face with outward normal ``n`` (a
    box axis): its depth behind that face (however deep, never through the opposite one), or its
    distance to a side face of that face's lateral extent where smaller (then that side's normal),
    so that the depth falls to 0 at the lateral edge of the face instead of jumping from 0 to the
    full depth there; depth <= 0: no contact (in front of the face or beside its extent). A point
    past the opposite face (gone through the box within the face's extent) keeps the full depth
    behind the face: measured to a side it was ~0 near the box's corners, and a pad's corner swept
    across a node let it through (a stiff cylinder in the contact fuzz, 2026-12-07). So the depth
    jumps at the opposite face's plane near the sides (from the side distance inside to at least the
    box's thickness past it, the normal from the side's to the face's): a wall that only a node
    already through the box meets, unlike the lateral edge, where the depth is continuous. The
    normal is minus the depth's gradient: the contact force is ``penalty_force(depth)`` along it,
    its Hessian ``penalty_stiffness(depth)`` times its outer product (``evaluate_node``)."""
    depth = float(-1.0)
    beyond = False  # past the opposite face: gone through the box
    for j in range(3):
        if n[j] != 0.0:
            depth = half[j] - n[j] * local[j]
            beyond = depth > 2.0 * half[j]
    normal = n
    if depth > 0.0:
        for j in range(3):
            if n[j] == 0.0:
                side = half[j] - wp.abs(local[j])
                if side <= 0.0:
                    depth = -1.0
                elif side < depth and not beyond:
                    depth = side
                    normal = axis_normal(j, wp.sign(local[j]))
    return depth, normal


@wp.func
def start_face_normal(x_start: wp.vec3, pos0: wp.vec3, rot0: wp.quat, half: wp.vec3, n: wp.vec3):
    """Outward normal (box frame) of the face that held a node at the substep start (``face_contact``
    at its start position in the box's start frame; ``n``, the lagged face, where it was not inside):
    the plane in which the lagged friction acts and the start depth the guess keeps."""
    depth, normal = face_contact(wp.quat_rotate_inv(rot0, x_start - pos0), half, n)
    if depth > 0.0:
        return normal
    return n


@wp.func
def face_penetration(local: wp.vec3, half: wp.vec3, n: wp.vec3):
    """Depth (m, > 0 inside) of ``face_contact``."""
    depth, normal = face_contact(local, half, n)
    return depth
