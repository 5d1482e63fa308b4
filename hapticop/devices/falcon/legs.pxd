# C types for legs.py's per-call float maths when Cython compiles it (setup.py); the .py is the source.
cimport cython

cdef class LegMaths:
    cdef readonly double cphi, sphi, sphi_b, cphi_b, u0, v0, a, a2, two_a, b, de

    @cython.locals(X=cython.double, c3=cython.double, t3=cython.double, s3=cython.double, K=cython.double,
                   rho2=cython.double, cosine=cython.double, t1=cython.double, n0=cython.double,
                   n1=cython.double)
    cpdef tuple ik(self, double x, double y, double z)

    @cython.locals(t1=cython.double, t2=cython.double, s3=cython.double, c3=cython.double, K=cython.double,
                   n0=cython.double, n1=cython.double, D=cython.double, c2s3=cython.double)
    cpdef tuple row(self, tuple leg)
