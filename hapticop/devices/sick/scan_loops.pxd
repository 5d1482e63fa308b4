# C types for scan_loops.py when Cython compiles it (setup.py); the .py is the source.
cimport cython

cdef int _NOT_A_DIGIT, _SPACE
cdef unsigned int _LOW_32
cdef double _NAN
cdef const unsigned char[::1] _NIBBLE

@cython.locals(end=Py_ssize_t, nibble="const unsigned char[::1]", bad=cython.bint, empty=cython.bint,
               wide=cython.bint, i=Py_ssize_t, n=Py_ssize_t, start=Py_ssize_t, value=cython.uint,
               char=cython.uchar, digit=cython.uint, width=Py_ssize_t)
cpdef Py_ssize_t decode_hex(const unsigned char[::1] body, Py_ssize_t pos, Py_ssize_t count, Py_ssize_t digits,
                            unsigned int[::1] out) except? -5

@cython.locals(n=Py_ssize_t, nan=cython.double, i=Py_ssize_t, value=cython.double)
cpdef scale_ranges(const unsigned int[::1] raw, double factor, double offset, double min_range, double[::1] out)

@cython.locals(i=Py_ssize_t, value=cython.double)
cpdef beam_angles(double start, double step, double[::1] out)
