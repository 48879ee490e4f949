/*
 * Registries of the live handles the wrapper gave out (instances, FMU states).
 *
 * An fmi2Component or fmi2FMUstate handed back by a host is valid only if it is in its
 * registry: the pointer is looked up, never dereferenced before that, so a freed, foreign or
 * made-up handle is refused without reading memory that may be gone (a magic number read
 * through it would be a read after free). A handle enters when it is created and leaves before
 * it is freed. A set of pointers: open addressing with linear probing and backward-shift
 * deletion, guarded by one mutex (hosts may run instances in different threads). Used by
 * the wrapper and the C controller FMU alike (dcs_registry.h; only libc and dcs_lock.h).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dcs_registry.h"

#ifdef _WIN32
#ifndef WIN32_LEAN_AND_MEAN
#define WIN32_LEAN_AND_MEAN
#endif
#include <windows.h>

/* DcsLock is an SRWLOCK by layout (dcs_lock.h) */
typedef char dcs_lock_is_an_srwlock[sizeof(DcsLock) == sizeof(SRWLOCK) ? 1 : -1];

void dcs_lock(DcsLock *l)
{
    AcquireSRWLockExclusive((PSRWLOCK)(void *)l);
}

void dcs_unlock(DcsLock *l)
{
    ReleaseSRWLockExclusive((PSRWLOCK)(void *)l);
}
#else
void dcs_lock(DcsLock *l)
{
    pthread_mutex_lock(l);
}

void dcs_unlock(DcsLock *l)
{
    pthread_mutex_unlock(l);
}
#endif

static size_t slot_of(const void *p, size_t cap)
{
    uint64_t h = (uint64_t)(uintptr_t)p;
    h ^= h >> 33; /* a murmur3 finaliser: pointers are aligned, their low bits all alike */
    h *= 0xff51afd7ed558ccdULL;
    h ^= h >> 33;
    return (size_t)(h & (cap - 1)); /* cap is a power of two */
}

/* Index of p in r, or of the empty slot where it would go (r->cap > r->n). */
static size_t find(const DcsRegistry *r, const void *p)
{
    size_t i = slot_of(p, r->cap);
    while (r->slots[i] != NULL && r->slots[i] != p)
        i = (i + 1) & (r->cap - 1);
    return i;
}

static int grow(DcsRegistry *r)
{
    size_t cap = r->cap ? 2 * r->cap : 16, i;
    const void **old = r->slots, **slots = (const void **)calloc(cap, sizeof *slots);
    int rc = -1;
    if (slots != NULL) {
        size_t old_cap = r->cap;
        r->slots = slots;
        r->cap = cap;
        for (i = 0; i < old_cap; i++)
            if (old[i] != NULL)
                r->slots[find(r, old[i])] = old[i];
        free((void *)old);
        rc = 0;
    }
    return rc;
}

int dcs_registry_add(DcsRegistry *r, const void *p)
{
    int rc = 0;
    dcs_lock(&r->lock);
    if (2 * (r->n + 1) > r->cap) /* load factor <= 1/2 */
        rc = grow(r);
    if (rc == 0) {
        size_t i = find(r, p);
        if (r->slots[i] == NULL) {
            r->slots[i] = p;
            r->n++;
        }
    }
    dcs_unlock(&r->lock);
    return rc;
}

int dcs_registry_contains(DcsRegistry *r, const void *p)
{
    int found;
    dcs_lock(&r->lock);
    found = p != NULL && r->cap > 0 && r->slots[find(r, p)] == p;
    dcs_unlock(&r->lock);
    return found;
}

int dcs_registry_remove(DcsRegistry *r, const void *p)
{
    int found;
    dcs_lock(&r->lock);
    found = p != NULL && r->cap > 0 && r->slots[find(r, p)] == p;
    if (found) {
        size_t hole = find(r, p), i = hole;
        r->slots[hole] = NULL;
        r->n--;
        /* backward shift: move up every later entry of the run whose home is not in
         * (hole, i], so that no lookup meets the hole before its entry */
        for (;;) {
            size_t home;
            i = (i + 1) & (r->cap - 1);
            if (r->slots[i] == NULL)
                break;
            home = slot_of(r->slots[i], r->cap);
            if ((i > hole && (home <= hole || home > i)) ||
                (i < hole && (home <= hole && home > i))) {
                r->slots[hole] = r->slots[i];
                r->slots[i] = NULL;
                hole = i;
            }
        }
    }
    dcs_unlock(&r->lock);
    return found;
}
