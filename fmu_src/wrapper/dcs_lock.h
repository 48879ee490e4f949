/*
 * A statically initialised lock: the one piece of the platform layer that must be a type (a
 * lock in a static variable needs its initialiser at compile time), so it is chosen here by the
 * preprocessor; every other operating-system call of the wrapper is a function of
 * dcs_platform.h, one file per platform.
 *
 * Shared by the native wrapper and the C controller FMU (fmu_src/c_controller ships this header
 * with dcs_registry.c/.h in its sources/). POSIX: a pthread mutex. Windows: a slim
 * reader/writer lock taken exclusively (kernel32, Vista and later; nothing to destroy, no
 * winpthreads DLL to ship with a mingw-w64 build).
 */
#ifndef DCS_LOCK_H
#define DCS_LOCK_H

#ifdef _WIN32
#ifndef WIN32_LEAN_AND_MEAN
#define WIN32_LEAN_AND_MEAN
#endif
#include <windows.h>
typedef SRWLOCK DcsLock;
#define DCS_LOCK_INIT SRWLOCK_INIT
static inline void dcs_lock(DcsLock *l)
{
    AcquireSRWLockExclusive(l);
}
static inline void dcs_unlock(DcsLock *l)
{
    ReleaseSRWLockExclusive(l);
}
#else
#include <pthread.h>
typedef pthread_mutex_t DcsLock;
#define DCS_LOCK_INIT PTHREAD_MUTEX_INITIALIZER
static inline void dcs_lock(DcsLock *l)
{
    pthread_mutex_lock(l);
}
static inline void dcs_unlock(DcsLock *l)
{
    pthread_mutex_unlock(l);
}
#endif

#endif
