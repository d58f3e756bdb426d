"""Layouts of the flat arrays the compiled kernels exchange: the one module that packs and unpacks them.

The simulator, the sensors and the controller meet in four small float64 arrays. Everywhere
else state has names; these index constants are the only place the positions are written down,
and the ``*_COLUMNS`` tuples give every slot a name and unit for logs.

Frames: world NED, body FRD (see :mod:`vtoladapt.frames`). Quaternions scalar first.
"""
from __future__ import annotations

import numpy as np

# --- plant state x ---------------------------------------------------------------------------
X_P_W = 0          # position, NED, m (3)
X_V_W = 3          # velocity, NED, m/s (3)
X_Q_WB = 6         # attitude quaternion q_WB, scalar first (4)
X_OMEGA_B = 10     # body rate, FRD, rad/s (3)
X_MOTOR = 13       # motor outputs after lag, fraction of full throttle: 4 lift rotors then pusher (5)
X_SIZE = 18
N_MOTORS = 5
N_LIFT = 4
MOTOR_PUSHER = 4

STATE_COLUMNS = (
    ("p_N_m", "p_E_m", "p_D_m", "v_N_mps", "v_E_mps", "v_D_mps", "q_w", "q_x", "q_y", "q_z",
     "omega_x_radps", "omega_y_radps", "omega_z_radps",
     "motor1_frac", "motor2_frac", "motor3_frac", "motor4_frac", "pusher_frac"))

# --- measurement (what the controller sees) ---------------------------------------------------
MEAS_P_W = 0        # motion-capture position, NED, m (3)
MEAS_V_W = 3        # motion-capture velocity, NED, m/s (3)
MEAS_Q_WB = 6       # attitude estimate q_WB (4)
MEAS_OMEGA_B = 10   # gyro, rad/s (3)
MEAS_ACCEL_B = 13   # accelerometer specific force a - g in body axes, m/s^2 (3)
MEAS_V_I_B = 16     # incident velocity from the airflow probe, body, m/s (3)
MEAS_V_I_VALID = 19 # 1.0 if the probe reading is valid, else 0.0
MEAS_SIZE = 20

MEASUREMENT_COLUMNS = (
    "meas_p_N_m", "meas_p_E_m", "meas_p_D_m", "meas_v_N_mps", "meas_v_E_mps", "meas_v_D_mps",
    "meas_q_w", "meas_q_x", "meas_q_y", "meas_q_z",
    "meas_omega_x_radps", "meas_omega_y_radps", "meas_omega_z_radps",
    "meas_accel_x_mps2", "meas_accel_y_mps2", "meas_accel_z_mps2",
    "meas_v_i_x_mps", "meas_v_i_y_mps", "meas_v_i_z_mps", "meas_v_i_valid")

# --- reference (what the controller is asked to do) -------------------------------------------
REF_P_W = 0         # desired position, NED, m (3)
REF_V_W = 3         # desired velocity, NED, m/s (3)
REF_A_W = 6         # desired acceleration, NED, m/s^2 (3)
REF_YAW = 9         # desired heading, rad
REF_YAW_RATE = 10   # desired heading rate, rad/s
REF_SIZE = 11

REFERENCE_COLUMNS = ("ref_p_N_m", "ref_p_E_m", "ref_p_D_m", "ref_v_N_mps", "ref_v_E_mps",
                     "ref_v_D_mps", "ref_a_N_mps2", "ref_a_E_mps2", "ref_a_D_mps2",
                     "ref_yaw_rad", "ref_yaw_rate_radps")

# --- command (what the controller outputs, held between ticks) --------------------------------
CMD_U_X = 0         # pusher throttle, fraction [0, 1]
CMD_U_Z = 1         # collective lift throttle, fraction [0, 1] (total lift = CTz_s u_z^2 per unit mass)
CMD_TAU_B = 2       # body moment command, FRD, N m (3)
CMD_SIZE = 5

COMMAND_COLUMNS = ("cmd_u_x_frac", "cmd_u_z_frac", "cmd_tau_x_Nm", "cmd_tau_y_Nm", "cmd_tau_z_Nm")

# --- wind --------------------------------------------------------------------------------------
WIND_COLUMNS = ("wind_N_mps", "wind_E_mps", "wind_D_mps")


def pack_state(p_W, v_W, q_WB, omega_B, motor_frac) -> np.ndarray:
    """Plant state vector from named parts."""
    x = np.zeros(X_SIZE)
    x[X_P_W:X_P_W + 3] = p_W
    x[X_V_W:X_V_W + 3] = v_W
    x[X_Q_WB:X_Q_WB + 4] = q_WB
    x[X_OMEGA_B:X_OMEGA_B + 3] = omega_B
    x[X_MOTOR:X_MOTOR + N_MOTORS] = motor_frac
    return x


def unpack_state(x: np.ndarray) -> dict[str, np.ndarray]:
    """Named views of a plant state vector (or of a ``(T, X_SIZE)`` history)."""
    return {"p_W": x[..., X_P_W:X_P_W + 3], "v_W": x[..., X_V_W:X_V_W + 3],
            "q_WB": x[..., X_Q_WB:X_Q_WB + 4], "omega_B": x[..., X_OMEGA_B:X_OMEGA_B + 3],
            "motor_frac": x[..., X_MOTOR:X_MOTOR + N_MOTORS]}


def pack_reference(p_W, v_W=(0.0, 0.0, 0.0), a_W=(0.0, 0.0, 0.0), yaw_rad=0.0,
                   yaw_rate_radps=0.0) -> np.ndarray:
    """Reference vector from named parts."""
    r = np.zeros(REF_SIZE)
    r[REF_P_W:REF_P_W + 3] = p_W
    r[REF_V_W:REF_V_W + 3] = v_W
    r[REF_A_W:REF_A_W + 3] = a_W
    r[REF_YAW] = yaw_rad
    r[REF_YAW_RATE] = yaw_rate_radps
    return r
