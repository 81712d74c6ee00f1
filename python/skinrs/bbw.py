"""Bounded biharmonic weights through the convex dual (filled in by issue 2)."""


def boundary_conditions(V, T, C, P=None, BE=None):
    raise NotImplementedError


def bbw_dual_constrained(V, T, b, bc, **kw):
    raise NotImplementedError


def bbw_dual(V, T, C, BE=None, P=None, **kw):
    raise NotImplementedError


def biharmonic_energy(W, B):
    raise NotImplementedError
