/* Arm semihosting (qemu -semihosting-config enable=on,target=native): console output on
   qemu's standard output (as cortex-m-semihosting's hprintln) and exit. */
#ifndef SEMIHOSTING_H
#define SEMIHOSTING_H

/* Writes a NUL-terminated string to the host's standard output. */
void sh_write(const char *s);

/* Ends the emulation, with exit status 0 if `success`, else 1. */
__attribute__((noreturn)) void sh_exit(int success);

#endif
