# C types for platform_dynamics.py when Cython compiles it (setup.py); the .py is the source.
cimport cython
from hapticop.devices.ropod.kinematics cimport inverse_sym3


cdef class PlatformDynamics:
    cdef readonly int units
    cdef readonly list rows, torque_sum, torque_diff, external
    cdef readonly double inv_r, k, inv_s, ic, friction, pivot_damping, mass, linear_damping, yaw_damping
    cdef readonly double d0, d1, d2, e0, e1, e2
    cdef list yt, k1, k2, k3, k4

    @cython.locals(units=cython.int, i=cython.int, j=cython.int, rows=list, torque_sum=list, torque_diff=list,
                   external=list, theta=cython.double, vx=cython.double, vy=cython.double, wz=cython.double,
                   c=cython.double, s=cython.double, inv_s=cython.double, inv_r=cython.double, k=cython.double,
                   ic=cython.double, friction=cython.double, fx=cython.double, fy=cython.double,
                   mz=cython.double, sdd=cython.double, w0=cython.double, w1=cython.double, w2=cython.double,
                   m00=cython.double, m01=cython.double, m02=cython.double, m11=cython.double,
                   m12=cython.double, m22=cython.double, ua=cython.double, ub=cython.double,
                   qa=cython.double, qb=cython.double, a=cython.double, b=cython.double, ci=cython.double,
                   si=cython.double, u3=cython.double, q3=cython.double, q=cython.double, u=cython.double,
                   dd=cython.double, w=cython.double, m=cython.double, ex=cython.double, ey=cython.double,
                   ez=cython.double, r0=cython.double, r1=cython.double, r2=cython.double,
                   i00=cython.double,
                   i01=cython.double, i02=cython.double, i11=cython.double, i12=cython.double,
                   i22=cython.double)
    cpdef derivative(self, list y, list dy)

    @cython.locals(yt=list, k1=list, k2=list, k3=list, k4=list, coupled_end=cython.int, j=cython.int,
                   hh=cython.double, h6=cython.double)
    cpdef rk4(self, list y, double h)
