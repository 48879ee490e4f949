/*
 * SHA-256 (FIPS 180-4), for the integrity check of a self-contained FMU's runtime
 * (dcs_runtime.c). Portable C99; tests/test_standalone_runtime.py compares it with Python's
 * hashlib on the files of a runtime.
 */
#ifndef DCS_SHA256_H
#define DCS_SHA256_H

#include <stddef.h>
#include <stdint.h>

typedef struct {
    uint32_t h[8];
    uint64_t bytes;      /* message length so far */
    unsigned char block[64];
    size_t used;         /* bytes in block */
} DcsSha256;

void dcs_sha256_init(DcsSha256 *s);
/* Whether the block function runs on the CPU's SHA extensions (x86-64 SHA-NI). */
int dcs_sha256_accelerated(void);
void dcs_sha256_update(DcsSha256 *s, const void *data, size_t n);
/* The digest as 64 lowercase hex digits and a NUL into hex[65]. */
void dcs_sha256_hex(DcsSha256 *s, char hex[65]);

#endif
