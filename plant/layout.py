"""Index constants of the flat float parameter vector ``p`` shared by the compiled kernels.

The kernels take plain arrays (numba compiles them once); ``plant/assembly.py`` fills ``p`` from a
:class:`~plant.params.PlantParams`: the scalar header (length ``NP``), then one record of ``NB``
values per body. Units are SI throughout.
"""

# geometry and inertia of one segment
DX = 0  # segment length [m]
HALF = 1  # dx / 2 [m]
MASS = 2  # segment mass [kg]
JT = 3  # transverse moment of inertia about G [kg m^2]
JP = 4  # polar moment of inertia [kg m^2]
GRAV = 5  # gravity along +Z (down the well) [m/s^2]
# joint springs (body i+1 frame) and dampers
K_AX = 6  # axial [N/m]
K_SH = 7  # shear [N/m]
K_BE = 8  # bending [N m/rad]
K_TO = 9  # torsion [N m/rad]
C_AX = 10  # [N s/m]
C_SH = 11
C_BE = 12  # [N m s/rad]
C_TO = 13
G1 = 14  # rotational potential V = 1/2 tr(G (I - R_rel)), G = diag(G1, G1, G3) [N m]
G3 = 15
# top drive joint (effective, half segment in series)
KT_AX = 16
KT_LAT = 17
KT_TO = 18
CT_AX = 19
CT_LAT = 20
CT_TO = 21
OMEGA0 = 22  # final rotary speed [rad/s]
T_RAMP = 23  # ramp time [s]
# bit
KB_AX = 24  # [N/m] (effective, 0 = free)
CB_AX = 25
ZBIT0 = 26  # static rock position [m]
BIT_AMP = 27  # [m]
BIT_LOBES = 28
BIT_TORQUE = 29  # [N m]
BIT_EPS = 30  # speed scale of the smoothed sign [rad/s]
# stabilizers, contact, unbalance, lateral drag, actuators
K_STAB = 31
C_STAB = 32
K_CONT = 33
C_CONT = 34
CLEAR = 35
UNB = 36  # m e [kg m]
ALPHA_LAT = 37  # lateral drag rate [1/s] (force = -alpha m v_lateral)
ACT_ARM = 38  # moment arm of an actuator pair: 2 r [m]
GAUGE_R = 39  # strain gauge radius [m]
# extensions beyond the paper (each off by default, see docs/physics.md)
TD_INERTIA = 40  # top-drive rotor inertia [kg m^2] (top_drive.mode = 'torque')
MU_WALL = 41  # Coulomb friction coefficient at the wellbore [1] (0 = off)
V_SLIP = 42  # slip speed of the regularized friction [m/s]
R_OUT = 43  # outer (collar) radius: contact point of the wall [m]
# cutting bit (bit.model = 'cutting', Detournay & Defourny 2008)
BIT_A = 44  # bit radius a [m]
BIT_EPSI = 45  # intrinsic specific energy epsilon [Pa]
BIT_ZETA = 46  # normal / tangential cutting force ratio [1]
BIT_WF = 47  # wear-flat force capacity W_f* [N]
BIT_MU = 48  # wear-flat friction coefficient mu gamma [1]
BIT_WEAK = 49  # static / dynamic friction - 1 [1]
BIT_WSPD = 50  # weakening speed [rad/s]
BIT_JX = 51  # polar inertia added to the bit body [kg m^2]
BIT_ZH0 = 52  # initial hole-bottom depth [m] (drilled depth = z_h - BIT_ZH0)
# field strings (sections, trajectory): the top drive's hoisting and frame
HOIST = 53  # hoisting speed of the top drive along its axis [m/s] (> 0 lowers the string)
TD_R = 54  # 9 values: frame of the top drive (body -> inertial, row-major) [1]
NP = 64  # length of the scalar header (a multiple of 8: records start on a cache line)

# Per-body records: p[NP + NB * k + field] for body k (0-based); the J_* fields describe the
# joint below body k (between bodies k and k + 1; unused for the last body). For the uniform
# pipe every record holds the scalars above, so that the kernels compute exactly the same.
# The first 8 fields are all the axial-torsional chain reads (one cache line a body).
B_IM = 0  # 1 / mass [1/kg]
B_W = 1  # weight along +Z (buoyed) [N]
B_IJP = 2  # 1 / polar moment of inertia [1/(kg m^2)]
J_KAX = 3  # joint below: axial stiffness [N/m]
J_CAX = 4  # axial damping [N s/m]
J_G1 = 5  # rotational potential G1 (= torsional stiffness) [N m]
J_CTO = 6  # torsional damping [N m s/rad]
J_LEN = 7  # distance between the two mass centres h_a + h_b [m]
B_M = 8  # mass [kg] (axial and rotational motion)
B_ML = 9  # lateral mass: mass + added mass of the mud [kg]
B_JT = 10  # transverse moment of inertia about G [kg m^2]
B_JP = 11  # polar moment of inertia [kg m^2]
B_H = 12  # half length [m]
B_CLIN = 13  # linear lateral drag [N s/m]
B_CQ = 14  # quadratic lateral drag [N s^2/m^2]
J_KSH = 15  # shear stiffness [N/m]
J_G3 = 16  # G3 = 2 k_bend - k_tors [N m]
J_CSH = 17  # shear damping [N s/m]
J_CBE = 18  # bending damping [N m s/rad]
J_RG = 19  # strain gauge radius at the joint [m]
J_ARM = 20  # moment arm of an actuator pair at the joint [m]
B_CLR = 21  # radial clearance of the body's mass centre to the wall [m]
B_RC = 22  # contact radius (outer radius touching the wall) [m]
B_K1 = 23  # curvature of the hole axis at the body, local x component [1/m]
B_K2 = 24  # ... local y component [1/m]
B_P = 25  # 3 values: reference point of the body's local frame (inertial) [m]
B_R = 28  # 9 values: reference frame of the body (local -> inertial, row-major) [1]
J_SF = 37  # outer-wall strain per radian of relative bending angle at the joint [1/m]
NB = 40  # (38 used; a multiple of 8)

# columns of the contact-point table in ``fp`` (after the load table; one row a point)
CP_BODY = 0  # 0-based body index
CP_Z = 1  # offset of the point from the mass centre along the body axis [m]
CP_CLR = 2  # radial clearance to the wall [m]
CP_RC = 3  # contact radius [m]
NCP = 4

# columns of the load table (one row a load)
LD_KIND = 0  # 0 force (inertial axis), 1 torque (body axis)
LD_BODY = 1  # 0-based body index
LD_DIR = 2  # 0 x, 1 y, 2 z
LD_MAG = 3
LD_T0 = 4  # switch-on time [s]
LD_T1 = 5  # switch-off time [s]
LD_ON = 6  # 1.0 while active: set per integration step by kernels.set_load_modes
NLD = 7
