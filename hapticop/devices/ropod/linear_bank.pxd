# C types for linear_bank.py's ControllerBank when Cython compiles it (setup.py); the .py is the source.
cimport cython

cdef class ControllerBank:
    cdef readonly int n
    cdef readonly double ts
    cdef readonly tuple _coef, _no_reset
    cdef readonly list _xi, _xd, _xl, _prev_reset, _y_pi, _y_leadlag, _clamped, _error, _reset, _out

    @cython.locals(j=cython.int, e=cython.double, k=cython.double, sat=cython.double, h_wi=cython.double,
                   dd=cython.double, ll_a=cython.double, ll_b=cython.double, g=cython.double,
                   lp_a=cython.double, x=cython.double, xi=cython.double, chk=cython.double,
                   hui=cython.double, clamped=cython.bint, ypi=cython.double, xd=cython.double,
                   w=cython.double, yll=cython.double, wl=cython.double,
                   xi_=list, xd_=list, xl_=list, prev=list, y_pi=list, y_ll=list, clamped_=list)
    cpdef step_values(self, error, list out, reset=*)
