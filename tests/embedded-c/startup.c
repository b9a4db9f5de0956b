/*
 * Start-up code of the bare-metal C firmware: the vector table, the reset handler (copies
 * .data, zeroes .bss, grants the FPU, calls main) and the fault handlers, which report over
 * semihosting and end the emulation with a failure.
 */
#include <stdint.h>

#include "semihosting.h"

extern uint32_t __sidata, __sdata, __edata, __sbss, __ebss, _stack_start;
extern int main(void);

void reset_handler(void);
void fault_handler(void);

/* Coprocessor access control (CP10/CP11 full access: the FPU). */
#define CPACR (*(volatile uint32_t *)0xE000ED88u)

void reset_handler(void) {
    uint32_t *src = &__sidata;
    uint32_t *dst = &__sdata;
    while (dst < &__edata) *dst++ = *src++;
    for (dst = &__sbss; dst < &__ebss; dst++) *dst = 0;
    CPACR |= 0xFu << 20;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    sh_exit(main() == 0);
}

void fault_handler(void) {
    sh_write("HardFault\n");
    sh_exit(0);
}

/* The initial stack pointer and the 15 system exceptions (the board's interrupts stay off). */
__attribute__((section(".vector_table"), used)) static const uintptr_t vector_table[16] = {
    (uintptr_t)&_stack_start,   (uintptr_t)reset_handler, (uintptr_t)fault_handler,
    (uintptr_t)fault_handler,   (uintptr_t)fault_handler, (uintptr_t)fault_handler,
    (uintptr_t)fault_handler,   0, 0, 0, 0,
    (uintptr_t)fault_handler,   (uintptr_t)fault_handler, 0,
    (uintptr_t)fault_handler,   (uintptr_t)fault_handler,
};
