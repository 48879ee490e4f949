/*
 * The serialized FMU state (see dcs_state_format.h): sealing, checking, SHA-256.
 *
 * Why SHA-256 and not a CRC: the checksum is also the state's content hash (checkpoints name a
 * state by it), hashlib checks it in Python without a second algorithm, and this plain
 * implementation (~210 MB/s) costs ~50 us of CPU for a plant state of 10.7 kB beside the ~430 us
 * Python spends encoding it (BENCHMARKS.md, "FMU state calls"). It guards against damage, not
 * against forgery: anyone can seal a state again (the FMU then checks its content as it checks
 * parameters).
 */
#include "dcs_state_format.h"

#include <stdio.h>
#include <string.h>

static const unsigned char MAGIC[8] = {'D', 'C', 'S', 'S', 'T', 'A', 'T', 'E'};

/* ---------------------------------------------------------------- little endian */
static void put_le(unsigned char *p, uint64_t v, int bytes)
{
    int i;
    for (i = 0; i < bytes; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static uint64_t get_le(const unsigned char *p, int bytes)
{
    uint64_t v = 0;
    int i;
    for (i = bytes - 1; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

void dcs_put_u32(unsigned char *p, uint32_t v)
{
    put_le(p, v, 4);
}

uint32_t dcs_get_u32(const unsigned char *p)
{
    return (uint32_t)get_le(p, 4);
}

void dcs_put_u64(unsigned char *p, uint64_t v)
{
    put_le(p, v, 8);
}

uint64_t dcs_get_u64(const unsigned char *p)
{
    return get_le(p, 8);
}

void dcs_put_f64(unsigned char *p, double v)
{
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits); /* double is IEEE 754 binary64 on every target we build */
    dcs_put_u64(p, bits);
}

double dcs_get_f64(const unsigned char *p)
{
    uint64_t bits = dcs_get_u64(p);
    double v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

/* ------------------------------------------------------------------- SHA-256 */
static const uint32_t K[64] = {
    0x428a2f98u, 0x71374491u, 0xb5c0fbcfu, 0xe9b5dba5u, 0x3956c25bu, 0x59f111f1u, 0x923f82a4u,
    0xab1c5ed5u, 0xd807aa98u, 0x12835b01u, 0x243185beu, 0x550c7dc3u, 0x72be5d74u, 0x80deb1feu,
    0x9bdc06a7u, 0xc19bf174u, 0xe49b69c1u, 0xefbe4786u, 0x0fc19dc6u, 0x240ca1ccu, 0x2de92c6fu,
    0x4a7484aau, 0x5cb0a9dcu, 0x76f988dau, 0x983e5152u, 0xa831c66du, 0xb00327c8u, 0xbf597fc7u,
    0xc6e00bf3u, 0xd5a79147u, 0x06ca6351u, 0x14292967u, 0x27b70a85u, 0x2e1b2138u, 0x4d2c6dfcu,
    0x53380d13u, 0x650a7354u, 0x766a0abbu, 0x81c2c92eu, 0x92722c85u, 0xa2bfe8a1u, 0xa81a664bu,
    0xc24b8b70u, 0xc76c51a3u, 0xd192e819u, 0xd6990624u, 0xf40e3585u, 0x106aa070u, 0x19a4c116u,
    0x1e376c08u, 0x2748774cu, 0x34b0bcb5u, 0x391c0cb3u, 0x4ed8aa4au, 0x5b9cca4fu, 0x682e6ff3u,
    0x748f82eeu, 0x78a5636fu, 0x84c87814u, 0x8cc70208u, 0x90befffau, 0xa4506cebu, 0xbef9a3f7u,
    0xc67178f2u};

static uint32_t rotr(uint32_t x, unsigned n)
{
    return (x >> n) | (x << (32u - n));
}

/* One 64-byte block into the hash value h (FIPS 180-4, 6.2.2). */
static void compress(uint32_t h[8], const unsigned char block[64])
{
    uint32_t w[64], a, b, c, d, e, f, g, k, t1, t2;
    int i;
    for (i = 0; i < 16; i++)
        w[i] = ((uint32_t)block[4 * i] << 24) | ((uint32_t)block[4 * i + 1] << 16) |
               ((uint32_t)block[4 * i + 2] << 8) | (uint32_t)block[4 * i + 3];
    for (i = 16; i < 64; i++) {
        uint32_t s0 = rotr(w[i - 15], 7) ^ rotr(w[i - 15], 18) ^ (w[i - 15] >> 3);
        uint32_t s1 = rotr(w[i - 2], 17) ^ rotr(w[i - 2], 19) ^ (w[i - 2] >> 10);
        w[i] = w[i - 16] + s0 + w[i - 7] + s1;
    }
    a = h[0]; b = h[1]; c = h[2]; d = h[3]; e = h[4]; f = h[5]; g = h[6]; k = h[7];
    for (i = 0; i < 64; i++) {
        t1 = k + (rotr(e, 6) ^ rotr(e, 11) ^ rotr(e, 25)) + ((e & f) ^ (~e & g)) + K[i] + w[i];
        t2 = (rotr(a, 2) ^ rotr(a, 13) ^ rotr(a, 22)) + ((a & b) ^ (a & c) ^ (b & c));
        k = g; g = f; f = e; e = d + t1; d = c; c = b; b = a; a = t1 + t2;
    }
    h[0] += a; h[1] += b; h[2] += c; h[3] += d; h[4] += e; h[5] += f; h[6] += g; h[7] += k;
}

void dcs_sha256(const void *data, size_t n, unsigned char digest[32])
{
    uint32_t h[8] = {0x6a09e667u, 0xbb67ae85u, 0x3c6ef372u, 0xa54ff53au,
                     0x510e527fu, 0x9b05688cu, 0x1f83d9abu, 0x5be0cd19u};
    const unsigned char *p = (const unsigned char *)data;
    unsigned char tail[128];
    size_t full = n / 64 * 64, rest = n - full, pad;
    uint64_t bits = (uint64_t)n * 8u;
    size_t i;
    for (i = 0; i < full; i += 64)
        compress(h, p + i);
    /* the padding: 0x80, zeros, the length in bits (big-endian) to a multiple of 64 bytes */
    memset(tail, 0, sizeof tail);
    if (rest > 0)
        memcpy(tail, p + full, rest);
    tail[rest] = 0x80;
    pad = rest < 56 ? 64 : 128;
    for (i = 0; i < 8; i++)
        tail[pad - 1 - i] = (unsigned char)(bits >> (8 * i));
    for (i = 0; i < pad; i += 64)
        compress(h, tail + i);
    for (i = 0; i < 8; i++) {
        digest[4 * i] = (unsigned char)(h[i] >> 24);
        digest[4 * i + 1] = (unsigned char)(h[i] >> 16);
        digest[4 * i + 2] = (unsigned char)(h[i] >> 8);
        digest[4 * i + 3] = (unsigned char)h[i];
    }
}

/* ------------------------------------------------------------------ the format */
const char *dcs_phase_name(unsigned phase)
{
    const char *name = "unknown";
    switch (phase) {
    case DCS_PHASE_INSTANTIATED: name = "Instantiated (before initialization)"; break;
    case DCS_PHASE_INITIALIZATION_MODE: name = "InitializationMode"; break;
    case DCS_PHASE_STEP_COMPLETE: name = "StepComplete"; break;
    case DCS_PHASE_TERMINATED: name = "Terminated"; break;
    default: break;
    }
    return name;
}

size_t dcs_state_size_for(size_t model_len, size_t build_len, size_t n)
{
    size_t fixed = DCS_STATE_HEADER + model_len + build_len + DCS_STATE_DIGEST;
    int fits = model_len <= DCS_STATE_MAX_ID && build_len <= DCS_STATE_MAX_ID &&
               n <= (size_t)-1 - fixed;
    return fits ? fixed + n : 0;
}

size_t dcs_state_seal(unsigned char *out, unsigned phase, const char *model, const char *build,
                      const unsigned char *payload, size_t n)
{
    size_t m = strlen(model), b = strlen(build);
    size_t size = dcs_state_size_for(m, b, n);
    if (size > 0) {
        memcpy(out, MAGIC, sizeof MAGIC);
        dcs_put_u32(out + 8, DCS_STATE_VERSION);
        dcs_put_u32(out + 12, phase);
        dcs_put_u32(out + 16, (uint32_t)m);
        dcs_put_u32(out + 20, (uint32_t)b);
        dcs_put_u64(out + 24, (uint64_t)n);
        memcpy(out + DCS_STATE_HEADER, model, m);
        memcpy(out + DCS_STATE_HEADER + m, build, b);
        if (n > 0)
            memcpy(out + DCS_STATE_HEADER + m + b, payload, n);
        dcs_sha256(out, size - DCS_STATE_DIGEST, out + size - DCS_STATE_DIGEST);
    }
    return size;
}

/* The header's problem (magic, version, lengths, checksum), in why, or 0 if it is sound. */
static int header_problem(const unsigned char *bytes, size_t size, char *why, size_t why_size)
{
    const size_t least = DCS_STATE_HEADER + DCS_STATE_DIGEST;
    unsigned char digest[DCS_STATE_DIGEST];
    uint32_t version, m, b;
    uint64_t n;
    int problem = 1;
    if (bytes == NULL || size < least) {
        snprintf(why, why_size, "%lu bytes: too short for a serialized FMU state (at least %lu)",
                 (unsigned long)(bytes == NULL ? 0 : size), (unsigned long)least);
    } else if (memcmp(bytes, MAGIC, sizeof MAGIC) != 0) {
        snprintf(why, why_size, "not a serialized drillcosim FMU state (it does not start with "
                 "DCSSTATE)");
    } else if ((version = dcs_get_u32(bytes + 8)) != DCS_STATE_VERSION) {
        snprintf(why, why_size, "format version %lu; this FMU reads version %u",
                 (unsigned long)version, DCS_STATE_VERSION);
    } else if ((m = dcs_get_u32(bytes + 16)) > size || (b = dcs_get_u32(bytes + 20)) > size ||
               (n = dcs_get_u64(bytes + 24)) > size || least + (uint64_t)m + b + n != size) {
        /* each length is bounded by size before they are added: no overflow */
        snprintf(why, why_size, "damaged: the lengths in its header do not match its %lu bytes",
                 (unsigned long)size);
    } else {
        dcs_sha256(bytes, size - DCS_STATE_DIGEST, digest);
        if (memcmp(digest, bytes + size - DCS_STATE_DIGEST, DCS_STATE_DIGEST) != 0)
            snprintf(why, why_size, "damaged: its SHA-256 checksum does not match its content");
        else
            problem = 0;
    }
    return problem;
}

int dcs_state_open(const unsigned char *bytes, size_t size, const char *model, const char *build,
                   DcsStateView *view, char *why, size_t why_size)
{
    int problem = header_problem(bytes, size, why, why_size);
    if (!problem) {
        view->phase = dcs_get_u32(bytes + 12);
        view->model_len = dcs_get_u32(bytes + 16);
        view->build_len = dcs_get_u32(bytes + 20);
        view->payload_len = (size_t)dcs_get_u64(bytes + 24);
        view->model = (const char *)bytes + DCS_STATE_HEADER;
        view->build = view->model + view->model_len;
        view->payload = bytes + DCS_STATE_HEADER + view->model_len + view->build_len;
        problem = 1;
        if (view->model_len != strlen(model) ||
            memcmp(view->model, model, view->model_len) != 0) {
            snprintf(why, why_size, "a state of FMU %.*s, not of %s",
                     (int)(view->model_len < 100 ? view->model_len : 100), view->model, model);
        } else if (view->build_len != strlen(build) ||
                   memcmp(view->build, build, view->build_len) != 0) {
            snprintf(why, why_size, "a state of build %.*s of %s; this FMU is build %s (states "
                     "move only between identical builds)",
                     (int)(view->build_len < 100 ? view->build_len : 100), view->build, model,
                     build[0] ? build : "(none)");
        } else if (!strcmp(dcs_phase_name(view->phase), "unknown")) {
            snprintf(why, why_size, "unknown phase %lu", (unsigned long)view->phase);
        } else {
            problem = 0;
        }
    }
    return problem;
}
