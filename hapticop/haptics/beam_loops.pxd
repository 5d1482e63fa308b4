# C types for beam_loops.py when Cython compiles it (setup.py); the .py is the source.
cimport cython

cdef double _INF

@cython.locals(clipped=cython.double)
cdef double _beyond(double v, double low, double high) noexcept

cdef class BeamBuffers:
    cdef readonly Py_ssize_t n
    cdef readonly double[::1] px, py, work, left, right
    cdef readonly unsigned char[::1] valid

    @cython.locals(work="double[::1]", value=cython.double, best=Py_ssize_t, low=cython.double, i=Py_ssize_t,
                   v=cython.double)
    cpdef double kth_smallest(self, Py_ssize_t lo, Py_ssize_t hi, int k)

    @cython.locals(px="double[::1]", py="double[::1]", valid="unsigned char[::1]", work="double[::1]",
                   i=Py_ssize_t, x=cython.double)
    cpdef double corridor_kth(self, double limit_y, double half_length, int k)

    @cython.locals(px="double[::1]", py="double[::1]", valid="unsigned char[::1]", left="double[::1]",
                   right="double[::1]", i=Py_ssize_t, x=cython.double, y=cython.double, inside=cython.bint)
    cpdef select_sides(self, double x_low, double x_high, double half_width)

    @cython.locals(px="double[::1]", py="double[::1]", work="double[::1]", penalty="double[::1]",
                   x_low=cython.double, x_high=cython.double, y_low=cython.double, y_high=cython.double,
                   i=Py_ssize_t, ex=cython.double, ey=cython.double)
    cpdef double side_kth_squared(self, bint left_side, Py_ssize_t lo, Py_ssize_t hi, double shift_x,
                                  double shift_y, double half_length, double half_width, int k)
