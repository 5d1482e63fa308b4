# C types for kinematics.py's per-cycle float maths when Cython compiles it (setup.py); the .py is the source.
# Its legs are legs.pxd's LegMaths, so the IK and Jacobian rows it asks them for are C calls.
cimport cython
from hapticop.devices.falcon.legs cimport LegMaths


cdef class FalconKinematics:
    cdef readonly object geometry, drive
    cdef public double tol_rad, tol_m, max_condition, residual
    cdef public int max_iterations, max_halvings, max_evaluations, warm_evaluations, iterations
    cdef readonly int _budget
    cdef readonly tuple _guess0, _Mt, _Q, _meas, _last
    cdef readonly LegMaths _leg1, _leg2, _leg3
    cdef readonly double _rad_per_count, _zero_rad, _motor_per_nm, _motor_cap, _det
    cdef readonly object _cur
    cdef readonly bint _have_last

    @cython.locals(leg1=tuple, leg2=tuple, leg3=tuple)
    cpdef tuple pose(self, double x, double y, double z)

    @cython.locals(r1=tuple, r2=tuple, r3=tuple, a00=cython.double, a01=cython.double, a02=cython.double,
                   a10=cython.double, a11=cython.double, a12=cython.double, a20=cython.double,
                   a21=cython.double, a22=cython.double, q00=cython.double, q01=cython.double,
                   q02=cython.double, q10=cython.double, q11=cython.double, q12=cython.double,
                   q20=cython.double, q21=cython.double, q22=cython.double, det=cython.double,
                   norm_m=cython.double, norm_q=cython.double)
    cpdef bint _jac(self, tuple pose) except -1

    @cython.locals(a=cython.double, b=cython.double, c=cython.double, r=cython.double, z=cython.double)
    cpdef bint forward(self, encoders, out_position) except -1

    @cython.locals(cur=tuple, solution=tuple, iterations=cython.int)
    cpdef bint _solve(self, out_position) except -1

    @cython.locals(tol_rad=cython.double, tol_m=cython.double, m0=cython.double, m1=cython.double,
                   m2=cython.double, x=cython.double, y=cython.double, z=cython.double, e0=cython.double,
                   e1=cython.double, e2=cython.double, rn=cython.double, converged=cython.bint, it=cython.int,
                   q00=cython.double, q01=cython.double, q02=cython.double, q10=cython.double,
                   q11=cython.double, q12=cython.double, q20=cython.double, q21=cython.double,
                   q22=cython.double, inv_det=cython.double, s0=cython.double, s1=cython.double,
                   s2=cython.double, norm=cython.double, lam=cython.double, trial=tuple, rt=cython.double,
                   _=cython.int, tx=cython.double, ty=cython.double, tz=cython.double, f0=cython.double,
                   f1=cython.double, f2=cython.double)
    cpdef tuple _newton(self, (double, double, double) p, tuple cur)

    @cython.locals(cur=tuple, pose=tuple)
    cpdef bint _pose(self, position) except -1

    @cython.locals(q00=cython.double, q01=cython.double, q02=cython.double, q10=cython.double,
                   q11=cython.double, q12=cython.double, q20=cython.double, q21=cython.double,
                   q22=cython.double, inv_det=cython.double)
    cpdef tuple _torques(self, double f0, double f1, double f2)

    @cython.locals(a00=cython.double, a01=cython.double, a02=cython.double, a10=cython.double,
                   a11=cython.double, a12=cython.double, a20=cython.double, a21=cython.double,
                   a22=cython.double)
    cpdef tuple pose_force(self, tuple pose, double tau1, double tau2, double tau3)

    @cython.locals(k=cython.double, m0=cython.double, m1=cython.double, m2=cython.double, peak=cython.double,
                   cap=cython.double, scale=cython.double)
    cpdef bint _motor(self, double t0, double t1, double t2, out_motor) except -1

    @cython.locals(f0=cython.double, f1=cython.double, f2=cython.double, t0=cython.double, t1=cython.double,
                   t2=cython.double)
    cpdef bint forces_to_motor(self, position, force, out_motor) except -1
