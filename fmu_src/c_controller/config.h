/* StrainControllerC: configuration of the FMU (names, value references, start values).
 *
 * The value references, names, units and start values are those of the Python
 * StrainController.fmu (fmu_src/strain_controller_fmu.py); modelDescription.xml beside
 * this file declares the same variables, and tests/test_c_controller.py checks that the
 * three agree.
 */
#ifndef DCS_CONFIG_H
#define DCS_CONFIG_H

#define MODEL_IDENTIFIER_STRING "StrainControllerC"
#define INSTANTIATION_TOKEN "{5c1d7e0a-3f4b-4f52-9a8e-2b6f1c0d7a31}"

/* Number of control channels: sites 1, 2 x gauges C, E (controller/strain_feedback.py CHANNELS). */
#define N_CHANNELS 4

/* Value references (the order of registration in the Python adapter). */
typedef enum {
    vr_strain1_C = 0,
    vr_strain1_E = 1,
    vr_strain2_C = 2,
    vr_strain2_E = 3,
    vr_actuator1_force_C = 4,
    vr_actuator1_force_E = 5,
    vr_actuator2_force_C = 6,
    vr_actuator2_force_E = 7,
    vr_gain = 8,
    vr_force_limit = 9,
    vr_symmetric_force_limit = 10,
    vr_switch_on_time = 11,
    vr_mode = 12,
    vr_lag_time_constant = 13,
    vr_enabled = 14
} ValueReference;

#define N_VARIABLES 15

/* Start values (controller/params.py ControllerParams defaults; 1e30 = "no symmetric limit"). */
#define START_GAIN 1e9
#define START_FORCE_LIMIT 5000.0
#define START_SYMMETRIC_FORCE_LIMIT 1e30
#define START_SWITCH_ON_TIME 0.0
#define START_MODE 0
#define START_LAG_TIME_CONSTANT 0.0
#define START_ENABLED 1

#endif /* DCS_CONFIG_H */
