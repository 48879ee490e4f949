/*
 * A statically initialised lock: the one piece of the platform layer that must be a type (a
 * lock in a static variable needs its initialiser at compile time), so it is chosen here by the
 * preprocessor; every other operating-system call of the wrapper is a function of
 * dcs_platform.h, one file per platform. dcs_lock/dcs_unlock are defined in dcs_registry.c.
 *
 * Shared by the native wrapper and the C controller FMU (fmu_src/c_controller ships this header
 * with dcs_registry.c/.h in its sources/). POSIX: a pthread mutex. Windows: a slim
 * reader/writer lock taken exclusively (kernel32, Vista and later; nothing to destroy, no
 * winpthreads DLL to ship with a mingw-w64 build), declared here by its layout (one pointer,
 * zero when free) so that only dcs_registry.c includes <windows.h> (the header costs mingw
 * most of a file's compile time).
 */
#ifndef DCS_LOCK_H
#define DCS_LOCK_H

#ifdef _WIN32
typedef struct {
    void *srwlock; /* an SRWLOCK, touched by kernel32 only */
} DcsLock;
#define DCS_LOCK_INIT {0}
#else
#include <pthread.h>
typedef pthread_mutex_t DcsLock;
#define DCS_LOCK_INIT PTHREAD_MUTEX_INITIALIZER
#endif

void dcs_lock(DcsLock *l);
void dcs_unlock(DcsLock *l);

#endif
