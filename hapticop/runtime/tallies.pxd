# C types for tallies.py when Cython compiles it (setup.py); the .py is the source.
cimport cython
from libc.stdint cimport int64_t

cdef class Histograms:
    cdef readonly int64_t[:, ::1] histogram
    cdef readonly int64_t[::1] maximum, closed
    cdef readonly Py_ssize_t rows, bins

    @cython.locals(us=int64_t)
    cpdef count(self, Py_ssize_t index, int64_t value_ns)

cdef class OriginMerge:
    cdef readonly int64_t[:, ::1] inputs, outputs
    cdef readonly int64_t[::1] newest

    @cython.locals(j=Py_ssize_t, i=Py_ssize_t, value=int64_t)
    cpdef merge(self)
