/* Arm semihosting calls: `bkpt 0xAB` with the operation in r0 and its argument in r1. */
#include <stddef.h>
#include <stdint.h>

#include "semihosting.h"

#define SYS_OPEN 0x01
#define SYS_WRITE 0x05
#define SYS_EXIT 0x18

static int call(int op, const void *arg) {
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

void sh_write(const char *s) {
    /* ":tt" opened for writing ("w", mode 4) is the host's standard output. */
    static int handle = -1;
    uintptr_t args[3];
    size_t n = 0;
    if (handle < 0) {
        args[0] = (uintptr_t)":tt";
        args[1] = 4;
        args[2] = 3;
        handle = call(SYS_OPEN, args);
    }
    while (s[n]) n++;
    args[0] = (uintptr_t)handle;
    args[1] = (uintptr_t)s;
    args[2] = n;
    call(SYS_WRITE, args);
}

void sh_exit(int success) {
    /* ADP_Stopped_ApplicationExit (exit status 0), ADP_Stopped_RunTimeErrorUnknown (1). */
    call(SYS_EXIT, (const void *)(uintptr_t)(success ? 0x20026 : 0x20023));
    for (;;) __asm__ volatile("wfi");
}
