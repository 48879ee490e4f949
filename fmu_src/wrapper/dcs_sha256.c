/*
 * SHA-256 (FIPS 180-4): see dcs_sha256.h.
 *
 * Two implementations of the block function: portable C, and on x86-64 the SHA extensions
 * (SHA-NI: Intel since Goldmont / Ice Lake, AMD since Zen), chosen once at run time from
 * CPUID. The portable one runs at ~0.1-0.3 GB/s, the SHA-NI one at ~1.5-2 GB/s: what the
 * runtime check costs at each start (dcs_runtime.c) depends on it. -DDCS_NO_SHA_NI builds the
 * portable one only (benchmarks/bench_standalone.py measures both).
 */
#include "dcs_sha256.h"

#include <string.h>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(DCS_NO_SHA_NI)
#define DCS_SHA_NI 1
#include <cpuid.h>
#include <immintrin.h>
#endif

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

#define ROTR(x, n) (((x) >> (n)) | ((x) << (32 - (n))))

static void compress(uint32_t h[8], const unsigned char *p)
{
    uint32_t w[64], a, b, c, d, e, f, g, k, t1, t2;
    int i;
    for (i = 0; i < 16; i++)
        w[i] = (uint32_t)p[4 * i] << 24 | (uint32_t)p[4 * i + 1] << 16 |
               (uint32_t)p[4 * i + 2] << 8 | (uint32_t)p[4 * i + 3];
    for (i = 16; i < 64; i++) {
        uint32_t s0 = ROTR(w[i - 15], 7) ^ ROTR(w[i - 15], 18) ^ (w[i - 15] >> 3);
        uint32_t s1 = ROTR(w[i - 2], 17) ^ ROTR(w[i - 2], 19) ^ (w[i - 2] >> 10);
        w[i] = w[i - 16] + s0 + w[i - 7] + s1;
    }
    a = h[0], b = h[1], c = h[2], d = h[3], e = h[4], f = h[5], g = h[6], k = h[7];
    for (i = 0; i < 64; i++) {
        t1 = k + (ROTR(e, 6) ^ ROTR(e, 11) ^ ROTR(e, 25)) + ((e & f) ^ (~e & g)) + K[i] + w[i];
        t2 = (ROTR(a, 2) ^ ROTR(a, 13) ^ ROTR(a, 22)) + ((a & b) ^ (a & c) ^ (b & c));
        k = g, g = f, f = e, e = d + t1, d = c, c = b, b = a, a = t1 + t2;
    }
    h[0] += a, h[1] += b, h[2] += c, h[3] += d, h[4] += e, h[5] += f, h[6] += g, h[7] += k;
}

#ifdef DCS_SHA_NI
/* The SHA-NI block function (the structure of Intel's "SHA extensions" paper): the state
 * as (ABEF, CDGH), four rounds per pair of sha256rnds2, the message schedule with
 * sha256msg1/msg2. */
__attribute__((target("sha,sse4.1"))) static void compress_ni(uint32_t h[8],
                                                                const unsigned char *p,
                                                                size_t blocks)
{
    const __m128i mask = _mm_set_epi64x(0x0c0d0e0f08090a0bULL, 0x0405060700010203ULL);
    __m128i tmp = _mm_loadu_si128((const __m128i *)(const void *)&h[0]);
    __m128i st1 = _mm_loadu_si128((const __m128i *)(const void *)&h[4]);
    __m128i st0;
    tmp = _mm_shuffle_epi32(tmp, 0xB1);  /* CDAB */
    st1 = _mm_shuffle_epi32(st1, 0x1B);  /* EFGH */
    st0 = _mm_alignr_epi8(tmp, st1, 8);  /* ABEF */
    st1 = _mm_blend_epi16(st1, tmp, 0xF0); /* CDGH */
    for (; blocks > 0; blocks--, p += 64) {
        __m128i save0 = st0, save1 = st1, w[4], msg;
        int j;
        for (j = 0; j < 16; j++) {
            __m128i *cur = &w[j & 3];
            if (j < 4) {
                *cur = _mm_shuffle_epi8(
                    _mm_loadu_si128((const __m128i *)(const void *)(p + 16 * j)), mask);
            } else { /* W[4j..4j+3] from the four groups before */
                __m128i t7 = _mm_alignr_epi8(w[(j - 1) & 3], w[(j - 2) & 3], 4);
                *cur = _mm_sha256msg1_epu32(*cur, w[(j - 3) & 3]); /* *cur held W[j-4] */
                *cur = _mm_sha256msg2_epu32(_mm_add_epi32(*cur, t7), w[(j - 1) & 3]);
            }
            msg = _mm_add_epi32(*cur, _mm_loadu_si128((const __m128i *)(const void *)&K[4 * j]));
            st1 = _mm_sha256rnds2_epu32(st1, st0, msg);
            st0 = _mm_sha256rnds2_epu32(st0, st1, _mm_shuffle_epi32(msg, 0x0E));
        }
        st0 = _mm_add_epi32(st0, save0);
        st1 = _mm_add_epi32(st1, save1);
    }
    tmp = _mm_shuffle_epi32(st0, 0x1B);    /* FEBA */
    st1 = _mm_shuffle_epi32(st1, 0xB1);    /* DCHG */
    st0 = _mm_blend_epi16(tmp, st1, 0xF0); /* DCBA */
    st1 = _mm_alignr_epi8(st1, tmp, 8);    /* HGFE */
    _mm_storeu_si128((__m128i *)(void *)&h[0], st0);
    _mm_storeu_si128((__m128i *)(void *)&h[4], st1);
}

static int has_sha_ni(void)
{
    static int known = -1;
    unsigned a, b, c, d;
    if (known < 0) {
        int ssse3_sse41 = __get_cpuid(1, &a, &b, &c, &d) && (c & (1u << 9)) && (c & (1u << 19));
        known = ssse3_sse41 && __get_cpuid_count(7, 0, &a, &b, &c, &d) && (b & (1u << 29));
    }
    return known;
}
#endif

/* blocks 64-byte blocks of p into the state */
int dcs_sha256_accelerated(void)
{
    int accelerated = 0;
#ifdef DCS_SHA_NI
    accelerated = has_sha_ni();
#endif
    return accelerated;
}

static void compress_blocks(uint32_t h[8], const unsigned char *p, size_t blocks)
{
#ifdef DCS_SHA_NI
    if (has_sha_ni()) {
        compress_ni(h, p, blocks);
        blocks = 0;
    }
#endif
    for (; blocks > 0; blocks--, p += 64)
        compress(h, p);
}

void dcs_sha256_init(DcsSha256 *s)
{
    static const uint32_t H0[8] = {0x6a09e667u, 0xbb67ae85u, 0x3c6ef372u, 0xa54ff53au,
                                   0x510e527fu, 0x9b05688cu, 0x1f83d9abu, 0x5be0cd19u};
    memcpy(s->h, H0, sizeof H0);
    s->bytes = 0;
    s->used = 0;
}

void dcs_sha256_update(DcsSha256 *s, const void *data, size_t n)
{
    const unsigned char *p = (const unsigned char *)data;
    s->bytes += n;
    if (s->used > 0) {
        size_t take = 64 - s->used < n ? 64 - s->used : n;
        memcpy(s->block + s->used, p, take);
        s->used += take;
        p += take;
        n -= take;
        if (s->used == 64) {
            compress_blocks(s->h, s->block, 1);
            s->used = 0;
        }
    }
    if (n >= 64) {
        compress_blocks(s->h, p, n / 64);
        p += n - n % 64;
        n %= 64;
    }
    if (n > 0) {
        memcpy(s->block, p, n);
        s->used = n;
    }
}

void dcs_sha256_hex(DcsSha256 *s, char hex[65])
{
    static const char digits[] = "0123456789abcdef";
    uint64_t bits = s->bytes * 8u;
    unsigned char pad[72];
    size_t npad = (s->used < 56 ? 56 : 120) - s->used, i;
    memset(pad, 0, sizeof pad);
    pad[0] = 0x80;
    for (i = 0; i < 8; i++)
        pad[npad + i] = (unsigned char)(bits >> (56 - 8 * i));
    dcs_sha256_update(s, pad, npad + 8);
    for (i = 0; i < 32; i++) {
        unsigned char byte = (unsigned char)(s->h[i / 4] >> (24 - 8 * (i % 4)));
        hex[2 * i] = digits[byte >> 4];
        hex[2 * i + 1] = digits[byte & 15];
    }
    hex[64] = '\0';
}
