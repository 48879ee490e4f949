/*
 * A mutex-guarded set of pointers: the live handles of one kind (dcs_registry.c).
 *
 * Shared by the native wrapper (instances, FMU states) and the C controller FMU
 * (fmu_src/c_controller, which ships this header and dcs_registry.c in its sources/): a handle
 * a host passes in is valid only if it is in its registry, so it is looked up, never probed
 * through a pointer that may be freed. Only the C standard library and a lock (dcs_lock.h:
 * pthreads, or Windows' slim reader/writer lock).
 */
#ifndef DCS_REGISTRY_H
#define DCS_REGISTRY_H

#include <stddef.h>

#include "dcs_lock.h"

typedef struct {
    DcsLock lock;
    const void **slots;
    size_t cap, n;
} DcsRegistry;
#define DCS_REGISTRY_INIT {DCS_LOCK_INIT, NULL, 0, 0}
int dcs_registry_add(DcsRegistry *r, const void *p);      /* 0, or -1 out of memory */
int dcs_registry_contains(DcsRegistry *r, const void *p); /* 1 if p is in r */
int dcs_registry_remove(DcsRegistry *r, const void *p);   /* 1 if p was in r (removed) */

#endif
