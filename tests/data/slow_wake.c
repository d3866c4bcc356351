// An LD_PRELOAD shim for tests/label_race.rs: every futex wake made through
// syscall() (libstdc++'s std::promise::set_value, among others) is followed
// by a pause of SLOW_WAKE_US microseconds (default 200) in the waking
// thread, which widens the window between a validation-layer thread's
// waking the application and its next steps.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <linux/futex.h>
#include <stdarg.h>
#include <stdlib.h>
#include <sys/syscall.h>
#include <time.h>

long syscall(long number, ...) {
    static long (*real)(long, ...) = 0;
    static long pause_us = -1;
    if (!real) real = (long (*)(long, ...))dlsym(RTLD_NEXT, "syscall");
    if (pause_us < 0) {
        const char *v = getenv("SLOW_WAKE_US");
        pause_us = v ? atol(v) : 200;
    }
    va_list ap;
    va_start(ap, number);
    long a[6];
    for (int i = 0; i < 6; i++) a[i] = va_arg(ap, long);
    va_end(ap);
    long r = real(number, a[0], a[1], a[2], a[3], a[4], a[5]);
    if (number == SYS_futex && (a[1] & FUTEX_CMD_MASK) == FUTEX_WAKE && pause_us > 0) {
        struct timespec t = {0, pause_us * 1000};
        nanosleep(&t, 0);
    }
    return r;
}
