// Test helper (LD_PRELOAD): counts the calls a process makes to write, writev, pwrite, fsync,
// fdatasync, rename, renameat, renameat2 and close, and at the n-th call either kills the
// process with SIGKILL (a crash at that point: nothing after it runs, no destructor, no cleanup)
// or makes that call fail with EIO. For the crash-safety test of map writing
// (maps/testing/map_crash_test.sh, docs/reliability.md).
//
// Environment:
//   EVLOC_FAULT_AT=N          the call (1-based, over every counted call) to act on; unset or 0:
//                             only count
//   EVLOC_FAULT_ACTION=kill   kill (default) or eio (the call returns -1 with errno EIO)
//   EVLOC_FAULT_CALLS=LIST    comma-separated names of the calls to count (default: all above)
//   EVLOC_FAULT_COUNT_FILE=F  at a normal exit, write the number of counted calls to F
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <unistd.h>

static atomic_long call_count;
static long fault_at = -1;  // -1: not read yet; 0: never.
static int fault_eio;
static const char* counted_calls;

static void ReadEnvironment(void) {
  const char* at = getenv("EVLOC_FAULT_AT");
  const char* action = getenv("EVLOC_FAULT_ACTION");
  fault_eio = action != NULL && strcmp(action, "eio") == 0;
  counted_calls = getenv("EVLOC_FAULT_CALLS");
  fault_at = at != NULL ? atol(at) : 0;
  if (fault_at < 0) fault_at = 0;
}

static int Counted(const char* name) {
  if (counted_calls == NULL || counted_calls[0] == '\0') return 1;
  const size_t length = strlen(name);
  for (const char* p = counted_calls; (p = strstr(p, name)) != NULL; p += length) {
    const int starts = p == counted_calls || p[-1] == ',';
    const int ends = p[length] == '\0' || p[length] == ',';
    if (starts && ends) return 1;
  }
  return 0;
}

// Counts one call of `name`; returns 1 when it must fail with EIO (kills for the kill action).
static int Fault(const char* name) {
  if (fault_at < 0) ReadEnvironment();
  if (!Counted(name)) return 0;
  const long n = atomic_fetch_add(&call_count, 1) + 1;
  if (fault_at == 0 || n != fault_at) return 0;
  if (!fault_eio) {
    kill(getpid(), SIGKILL);
    pause();
  }
  errno = EIO;
  return 1;
}

__attribute__((destructor)) static void WriteCount(void) {
  const char* path = getenv("EVLOC_FAULT_COUNT_FILE");
  if (path == NULL) return;
  FILE* file = fopen(path, "w");
  if (file == NULL) return;
  fprintf(file, "%ld\n", atomic_load(&call_count));
  fclose(file);
}

// Through uintptr_t: ISO C has no object-to-function pointer conversion, POSIX guarantees it.
#define NEXT(name) ((__typeof__(&name))(uintptr_t)dlsym(RTLD_NEXT, #name))

ssize_t write(int fd, const void* data, size_t size) {
  if (Fault("write")) return -1;
  return NEXT(write)(fd, data, size);
}

ssize_t writev(int fd, const struct iovec* iov, int count) {
  if (Fault("write")) return -1;
  return NEXT(writev)(fd, iov, count);
}

ssize_t pwrite(int fd, const void* data, size_t size, off_t offset) {
  if (Fault("write")) return -1;
  return NEXT(pwrite)(fd, data, size, offset);
}

int fsync(int fd) {
  if (Fault("fsync")) return -1;
  return NEXT(fsync)(fd);
}

int fdatasync(int fd) {
  if (Fault("fsync")) return -1;
  return NEXT(fdatasync)(fd);
}

int rename(const char* from, const char* to) {
  if (Fault("rename")) return -1;
  return NEXT(rename)(from, to);
}

int renameat(int from_dir, const char* from, int to_dir, const char* to) {
  if (Fault("rename")) return -1;
  return NEXT(renameat)(from_dir, from, to_dir, to);
}

int renameat2(int from_dir, const char* from, int to_dir, const char* to, unsigned int flags) {
  if (Fault("rename")) return -1;
  return NEXT(renameat2)(from_dir, from, to_dir, to, flags);
}

int close(int fd) {
  // A failed close still releases the descriptor (Linux), as the real one does.
  if (Fault("close")) {
    NEXT(close)(fd);
    return -1;
  }
  return NEXT(close)(fd);
}
