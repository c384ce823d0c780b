"""Joints between marker ports (docs/joints.md, docs/marker-ports.md), written a
second time from the documentation: marker kinematics from the 24 outputs, the
two fundamental conditions (point d.e, perpendicular a.b) with their velocity
and acceleration levels and force laws, the ten joint kinds as lists of
conditions, the planar reduction, and the force-port rows.

Vectors are 3-tuples of floats and every product is written out, left to
right, so that each number is one definite sequence of IEEE operations
(docs/validation.md, "Bit-for-bit joints").
"""

import math

from errors import RunError

KINDS = ("atpoint", "inplane", "perpendicular", "universal", "revolute", "cylindrical",
         "translational", "planar", "inline", "orientation")

X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


# -- 3-vectors -------------------------------------------------------------------------

def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def neg(a):
    return (-a[0], -a[1], -a[2])


def scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def rotate(rot, x):
    """rot (rows) times x."""
    return tuple(rot[i][0] * x[0] + rot[i][1] * x[1] + rot[i][2] * x[2] for i in range(3))


def norm(a):
    return math.sqrt(dot(a, a))


# -- marker outputs and kinematics ------------------------------------------------------

def marker_outputs(marker):
    """The 24 output names of a marker: r, R (row by row), v, w, a, alpha."""
    names = [f"{marker}.r[{k}]" for k in (1, 2, 3)]
    names += [f"{marker}.R[{i},{j}]" for i in (1, 2, 3) for j in (1, 2, 3)]
    for q in ("v", "w", "a", "alpha"):
        names += [f"{marker}.{q}[{k}]" for k in (1, 2, 3)]
    return names


class Kinematics:
    """Marker origin r, rotation, angular velocity and acceleration, and the
    attachment point C = r + R.offset with its velocity and acceleration."""

    def __init__(self, values, offset):
        s = values
        self.r = (s[0], s[1], s[2])
        self.rot = ((s[3], s[4], s[5]), (s[6], s[7], s[8]), (s[9], s[10], s[11]))
        v = (s[12], s[13], s[14])
        self.w = (s[15], s[16], s[17])
        a = (s[18], s[19], s[20])
        self.alpha = (s[21], s[22], s[23])
        self.rho = rotate(self.rot, offset)
        w_rho = cross(self.w, self.rho)
        self.c = add(self.r, self.rho)
        self.c_dot = add(v, w_rho)
        self.c_ddot = add(add(a, cross(self.alpha, self.rho)), cross(self.w, w_rho))

    def body_vector(self, local):
        """e, de/dt, d2e/dt2 of a vector fixed on the body (marker coordinates)."""
        e = rotate(self.rot, local)
        e1 = cross(self.w, e)
        e2 = add(cross(self.alpha, e), cross(self.w, e1))
        return e, e1, e2


def combine(level, g, g1, g2):
    if level == "position":
        return g
    if level == "velocity":
        return g1
    if level == "acceleration":
        return g2
    mu = level[1]  # ("stabilised", mu): the explicit method's condition
    return g2 + (2.0 * g1 / mu + g / (mu * mu))


# -- conditions -----------------------------------------------------------------------------

class Point:
    """(C_i - C_j).e = 0, e a world axis (atpoint) or fixed on side j (inplane)."""

    def __init__(self, e, on_j):
        self.e = e
        self.on_j = on_j

    def value(self, level, ki, kj):
        d = sub(ki.c, kj.c)
        d1 = sub(ki.c_dot, kj.c_dot)
        d2 = sub(ki.c_ddot, kj.c_ddot)
        if not self.on_j:
            return combine(level, dot(d, self.e), dot(d1, self.e), dot(d2, self.e))
        e, e1, e2 = kj.body_vector(self.e)
        return combine(level, dot(d, e), dot(d1, e) + dot(d, e1),
                       dot(d2, e) + 2.0 * dot(d1, e1) + dot(d, e2))

    def law(self, ki, kj):
        """[F_i, T_i, F_j, T_j] per unit multiplier, torques about the marker origins."""
        if self.on_j:
            e, arm_j = rotate(kj.rot, self.e), sub(ki.c, kj.r)  # j is pushed at C_i
        else:
            e, arm_j = self.e, kj.rho
        return e + cross(ki.rho, e) + neg(e) + cross(arm_j, neg(e))

    def loads(self, offset_i, offset_j):
        """Which of F_i, T_i, F_j, T_j the law can make non-zero."""
        return [True, norm(offset_i) > 0.0, True, self.on_j or norm(offset_j) > 0.0]

    def in_plane(self):
        return math.hypot(self.e[0], self.e[1]) > 1e-12


class Perpendicular:
    """a.b = 0, a fixed on side i, b on side j."""

    def __init__(self, a, b):
        self.a = a
        self.b = b

    def value(self, level, ki, kj):
        a, a1, a2 = ki.body_vector(self.a)
        b, b1, b2 = kj.body_vector(self.b)
        return combine(level, dot(a, b), dot(a1, b) + dot(a, b1),
                       dot(a2, b) + 2.0 * dot(a1, b1) + dot(a, b2))

    def law(self, ki, kj):
        t = cross(rotate(ki.rot, self.a), rotate(kj.rot, self.b))
        return (0.0, 0.0, 0.0) + t + (0.0, 0.0, 0.0) + neg(t)

    def loads(self, offset_i, offset_j):
        return [False, True, False, True]

    def in_plane(self):
        return math.hypot(self.a[0], self.a[1]) > 1e-12 and math.hypot(self.b[0], self.b[1]) > 1e-12


def frame(axis, reference, side):
    """(x, y, z) of a joint frame from its z axis and reference x axis."""
    n = norm(axis)
    if not n > 1e-12:
        raise ValueError(f"axis_{side} is zero")
    z = (axis[0] / n, axis[1] / n, axis[2] / n)
    x = sub(reference, scale(z, dot(reference, z)))
    n = norm(x)
    if not n > 1e-9:
        raise ValueError(f"ref_{side} is zero or parallel to axis_{side}")
    x = (x[0] / n, x[1] / n, x[2] / n)
    return x, cross(z, x), z


def conditions(kind, fi, fj):
    """The conditions of a joint kind (docs/joints.md, "Joint kinds")."""
    (xi, yi, zi), (xj, yj, zj) = fi, fj
    atpoint = [Point(X, False), Point(Y, False), Point(Z, False)]
    return {
        "atpoint": atpoint,
        "inplane": [Point(zj, True)],
        "perpendicular": [Perpendicular(zi, zj)],
        "universal": atpoint + [Perpendicular(xi, yj)],
        "revolute": atpoint + [Perpendicular(xi, zj), Perpendicular(yi, zj)],
        "cylindrical": [Perpendicular(xi, zj), Perpendicular(yi, zj), Point(xj, True), Point(yj, True)],
        "translational": [Perpendicular(xi, zj), Perpendicular(yi, zj), Perpendicular(xi, yj),
                          Point(xj, True), Point(yj, True)],
        "planar": [Perpendicular(xi, zj), Perpendicular(yi, zj), Point(zj, True)],
        "inline": [Point(xj, True), Point(yj, True)],
        "orientation": [Perpendicular(xi, zj), Perpendicular(yi, zj), Perpendicular(xi, yj)],
    }.get(kind)


# -- joints as rows ---------------------------------------------------------------------------

class Side:
    def __init__(self, instance, marker, offset):
        self.instance = instance
        self.marker = marker
        self.offset = offset
        self.names = marker_outputs(marker)

    def kinematics(self, output):
        return Kinematics([output(self.instance, name, 0) for name in self.names], self.offset)


class Joint:
    """A `[[joint]]`, resolved to its conditions (after the planar reduction)."""

    def __init__(self, spec):
        self.name = spec.name

        def fail(reason):
            return RunError(f"joint '{spec.name}': {reason}")

        def vector(v, default):
            return default if v is None else tuple(float(x) for x in v)

        try:
            fi = frame(vector(spec.axis_i, Z), vector(spec.ref_i, X), "i")
            fj = frame(vector(spec.axis_j, Z), vector(spec.ref_j, X), "j")
        except ValueError as e:
            raise fail(str(e)) from None
        found = conditions(spec.kind, fi, fj)
        if found is None:
            raise fail(f"unknown kind '{spec.kind}'; kinds are: {', '.join(KINDS)}")
        if spec.plane not in (None, "xy"):
            raise fail(f"plane = \"{spec.plane}\" is not supported; use \"xy\" or leave it out")
        self.planar = spec.plane == "xy"
        if self.planar:
            found = [c for c in found if c.in_plane()]
            if not found:
                raise fail(f"a {spec.kind} joint has no condition acting in the xy-plane")
        self.conditions = found
        self.offsets = (vector(spec.offset_i, (0.0, 0.0, 0.0)), vector(spec.offset_j, (0.0, 0.0, 0.0)))
        self.sides = []
        for text, offset in zip((spec.i, spec.j), self.offsets):
            instance, dot_, marker = text.partition(".")
            if not dot_:
                raise fail(f"marker '{text}' must be written <instance>.<marker>")
            self.sides.append(Side(instance, marker, offset))
        if spec.initial is not None and len(spec.initial) != len(found):
            raise fail(f"initial has {len(spec.initial)} values but the joint has {len(found)} conditions")
        if spec.multipliers is not None and len(spec.multipliers) != len(found):
            raise fail(f"multipliers has {len(spec.multipliers)} expressions but the joint has "
                       f"{len(found)} conditions")

    def kinematics(self, output):
        cache = getattr(output, "cache", None)
        if cache is None:
            return self.sides[0].kinematics(output), self.sides[1].kinematics(output)
        if id(self) not in cache:
            cache[id(self)] = (self.sides[0].kinematics(output), self.sides[1].kinematics(output))
        return cache[id(self)]

    def reads(self):
        return [(side.instance, name, 0) for side in self.sides for name in side.names]

    def port_components(self):
        """(side, quantity, axis, component 0..11, loading conditions) for every
        port component some condition can load, in column order."""
        out = []
        for side in (0, 1):
            for part, quantity in ((0, "F"), (1, "T")):
                for axis in range(3):
                    if self.planar and (axis == 2) == (part == 0):
                        continue  # in the plane: F x/y and T z only
                    loading = [k for k, c in enumerate(self.conditions)
                               if c.loads(*self.offsets)[side * 2 + part]]
                    if loading:
                        out.append((side, quantity, axis, side * 6 + part * 3 + axis, loading))
        return out


class ConditionRow:
    """Condition k of a joint: g, dg/dt, d2g/dt2 from the two markers."""

    levels = ("position", "velocity", "acceleration")
    algebraic = False

    def __init__(self, joint, k):
        self.joint = joint
        self.k = k
        self.residual = f"{joint.name}.g[{k + 1}]"

    def reads(self, level):
        return self.joint.reads()

    def value(self, level, output, u):
        ki, kj = self.joint.kinematics(output)
        return self.joint.conditions[self.k].value(level, ki, kj)


class PortRow:
    """A force or torque input driven by its own unknown p:
    p - sum over (joint, condition) of lambda * law component = 0, on every level."""

    levels = ("position", "velocity", "acceleration")
    algebraic = True
    residual = None

    def __init__(self, unknown):
        self.unknown = unknown
        self.contributions = []  # (joint, first multiplier index, condition, component)

    def reads(self, level):
        return [r for joint, _, _, _ in self.contributions for r in joint.reads()]

    def value(self, level, output, u):
        force = 0.0
        for joint, first, k, component in self.contributions:
            ki, kj = joint.kinematics(output)
            force += u[first + k] * joint.conditions[k].law(ki, kj)[component]
        return u[self.unknown] - force
