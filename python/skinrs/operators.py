"""Discrete operators (filled in by issue 2)."""


def cotan_laplacian(V, F):
    raise NotImplementedError


def massmatrix(V, F, kind="voronoi"):
    raise NotImplementedError


def biharmonic_matrix(V, F, mass="voronoi"):
    raise NotImplementedError
