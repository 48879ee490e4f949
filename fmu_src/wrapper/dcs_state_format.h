/*
 * The serialized FMU state of every drillcosim FMU (format version 1): a header, the identity of
 * the FMU and build, the FMU's payload and a SHA-256 of all of it (dcs_state_format.c).
 *
 * Shared by the native wrapper (dcs_state.c) and the C controller FMU (fmu_src/c_controller, which
 * ships this header and dcs_state_format.c in its sources/), as dcs_registry.h is. Pure C99: no
 * Python, no threads, no platform calls. The layout (docs/reliability.md, "FMU state"; a second
 * implementation in fmu_src/state_format.py), all integers little-endian:
 *
 *     offset  bytes  field
 *     0       8      magic "DCSSTATE"
 *     8       4      format version (uint32) = 1
 *     12      4      phase (uint32): the FMI 2.0 state the instance was in, DCS_PHASE_*
 *     16      4      length m of the model identifier (1..255)
 *     20      4      length b of the build identifier (0..255)
 *     24      8      length n of the payload (uint64)
 *     32      m      model identifier
 *     32+m    b      build identifier
 *     32+m+b  n      payload (the FMU's own)
 *     end-32  32     SHA-256 of every byte before it
 */
#ifndef DCS_STATE_FORMAT_H
#define DCS_STATE_FORMAT_H

#include <stddef.h>
#include <stdint.h>

#define DCS_STATE_VERSION 1u
#define DCS_STATE_HEADER 32u
#define DCS_STATE_DIGEST 32u
#define DCS_STATE_MAX_ID 255u /* longest model or build identifier */

/* The phases (the FMI 2.0 states a state can be taken in), one bit each as the wrapper's DcsState
 * and the C controller's ModelState. */
#define DCS_PHASE_INSTANTIATED 1u
#define DCS_PHASE_INITIALIZATION_MODE 2u
#define DCS_PHASE_STEP_COMPLETE 4u
#define DCS_PHASE_TERMINATED 8u

/* What a serialized state holds (pointers into its bytes). */
typedef struct {
    unsigned phase;
    const char *model, *build; /* not NUL-terminated */
    size_t model_len, build_len;
    const unsigned char *payload;
    size_t payload_len;
} DcsStateView;

/* Bytes of a serialized state with identifiers of these lengths and a payload of n bytes; 0 if
 * an identifier is too long or the size overflows. */
size_t dcs_state_size_for(size_t model_len, size_t build_len, size_t n);

/* Write the serialized state into out (dcs_state_size_for(...) bytes). model and build are
 * NUL-terminated; returns the number of bytes written (0: an identifier too long). */
size_t dcs_state_seal(unsigned char *out, unsigned phase, const char *model, const char *build,
                      const unsigned char *payload, size_t n);

/* Check the serialized state bytes[0..size) against this FMU's model and build identifiers
 * (NUL-terminated): 0 and *view filled, or nonzero with a one-line reason in why (magic, version,
 * lengths, checksum, model, build, phase: in this order). */
int dcs_state_open(const unsigned char *bytes, size_t size, const char *model, const char *build,
                   DcsStateView *view, char *why, size_t why_size);

/* Name of a phase ("StepComplete", ...; "unknown" for any other value). */
const char *dcs_phase_name(unsigned phase);

/* SHA-256 (FIPS 180-4) of data[0..n). */
void dcs_sha256(const void *data, size_t n, unsigned char digest[32]);

/* Little-endian scalars at p (the payload layouts use them: no struct is copied as bytes). */
void dcs_put_u32(unsigned char *p, uint32_t v);
uint32_t dcs_get_u32(const unsigned char *p);
void dcs_put_u64(unsigned char *p, uint64_t v);
uint64_t dcs_get_u64(const unsigned char *p);
void dcs_put_f64(unsigned char *p, double v); /* IEEE 754 binary64, bit for bit */
double dcs_get_f64(const unsigned char *p);

#endif
