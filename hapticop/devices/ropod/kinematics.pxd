# C types for kinematics.py's per-cycle float methods when Cython compiles it (setup.py); the .py is the source.
cimport cython

@cython.locals(c00=cython.double, c01=cython.double, c02=cython.double, det=cython.double, inv=cython.double)
cpdef tuple inverse_sym3(double n00, double n01, double n02, double n11, double n12, double n22)

cdef class SmartWheelKinematics:
    cdef readonly object geometry
    cdef readonly int units, wheels
    cdef readonly double _inv_r, _inv_s, _k
    cdef readonly tuple unit_rows, _n, _n_inv
    cdef readonly list _units, unit_mask

    @cython.locals(units=list, mask=list, k2=cython.double, one_minus_k2=cython.double, n00=cython.double,
                   n01=cython.double, n02=cython.double, n11=cython.double, n12=cython.double, n22=cython.double,
                   i=cython.int, d=cython.double, ua=cython.double, ub=cython.double, qa=cython.double,
                   qb=cython.double, c=cython.double, s=cython.double, u3=cython.double, q3=cython.double,
                   on=cython.double, cc=cython.double, ss=cython.double, f=cython.double, det=cython.double,
                   i00=cython.double, i01=cython.double, i02=cython.double, i11=cython.double,
                   i12=cython.double, i22=cython.double)
    cpdef evaluate(self, delta, enable=*)

    @cython.locals(k=cython.double, a0=cython.double, a1=cython.double, a2=cython.double, i=cython.int,
                   c=cython.double, s=cython.double, u3=cython.double, q3=cython.double, m=cython.double,
                   p1=cython.double, p2=cython.double, a=cython.double, b=cython.double, inv_r=cython.double,
                   i00=cython.double, i01=cython.double, i02=cython.double, i11=cython.double,
                   i12=cython.double, i22=cython.double)
    cpdef tuple twist_of(self, wheel_speeds)

    @cython.locals(k=cython.double, inv_r=cython.double, i=cython.int, c=cython.double, s=cython.double,
                   u3=cython.double, q3=cython.double, u=cython.double, q=cython.double)
    cpdef wheel_speeds_into(self, double vx, double vy, double wz, list out)

    @cython.locals(inv_s=cython.double, i=cython.int, c=cython.double, s=cython.double, q3=cython.double)
    cpdef pivot_rates_into(self, double vx, double vy, double wz, list out)

    @cython.locals(k=cython.double, inv_r=cython.double, fx=cython.double, fy=cython.double, mz=cython.double,
                   i=cython.int, c=cython.double, s=cython.double, u3=cython.double, q3=cython.double,
                   t1=cython.double, t2=cython.double, a=cython.double, b=cython.double)
    cpdef tuple wrench_of(self, torques)

    @cython.locals(i00=cython.double, i01=cython.double, i02=cython.double, i11=cython.double,
                   i12=cython.double, i22=cython.double, x0=cython.double, x1=cython.double, x2=cython.double,
                   k=cython.double, inv_r=cython.double, peak=cython.double, i=cython.int, j=cython.int,
                   c=cython.double, s=cython.double, u3=cython.double, q3=cython.double, m=cython.double,
                   u=cython.double, q=cython.double, t1=cython.double, t2=cython.double, scale=cython.double)
    cpdef double distribute_into(self, double fx, double fy, double mz, double tau_max, list out)
