/*
 * gf_simavr_harness: run an AVR test firmware under libsimavr and collect what it reports.
 *
 * Usage: gf_simavr_harness FIRMWARE.elf MCU FREQ_HZ OUT.bin CYCLES.txt
 *
 * The firmware (grasprom.export.arduino, gf_avr_test_main.c) writes result bytes to GPIOR0 and step
 * markers to GPIOR1 (1 = step begins, 2 = step ends); the harness appends the bytes to OUT.bin
 * and the simulated cycle count between markers, one line per step, to CYCLES.txt; it stops
 * when the firmware sleeps with interrupts off (cpu_Done).  Exit status 0 on a clean stop.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_io.h>

#define GPIOR0_ADDR 0x3E /* data-space address of GPIOR0 (I/O 0x1E) on the ATmega328P */
#define GPIOR1_ADDR 0x4A /* GPIOR1 (I/O 0x2A) */

static FILE *g_out, *g_cyc;
static avr_cycle_count_t g_start;

static void on_data(struct avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
    (void)avr; (void)addr; (void)param;
    fputc(v, g_out);
}

static void on_mark(struct avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
    (void)addr; (void)param;
    if (v == 1) g_start = avr->cycle;
    else if (v == 2) fprintf(g_cyc, "%llu\n", (unsigned long long)(avr->cycle - g_start));
}

int main(int argc, char **argv) {
    elf_firmware_t fw;
    avr_t *avr;
    int state;
    unsigned long long limit;
    if (argc != 6) {
        fprintf(stderr, "usage: %s FIRMWARE.elf MCU FREQ_HZ OUT.bin CYCLES.txt\n", argv[0]);
        return 2;
    }
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(argv[1], &fw) != 0) { fprintf(stderr, "cannot read %s\n", argv[1]); return 2; }
    avr = avr_make_mcu_by_name(argv[2]);
    if (!avr) { fprintf(stderr, "unknown MCU %s\n", argv[2]); return 2; }
    avr_init(avr);
    avr->log = 0;
    fw.frequency = (uint32_t)strtoul(argv[3], NULL, 10);
    avr_load_firmware(avr, &fw);
    g_out = fopen(argv[4], "wb");
    g_cyc = fopen(argv[5], "w");
    if (!g_out || !g_cyc) { fprintf(stderr, "cannot open the output files\n"); return 2; }
    avr_register_io_write(avr, GPIOR0_ADDR, on_data, NULL);
    avr_register_io_write(avr, GPIOR1_ADDR, on_mark, NULL);
    limit = 4000000000ULL;
    do {
        state = avr_run(avr);
    } while (state != cpu_Done && state != cpu_Crashed && avr->cycle < limit);
    fclose(g_out);
    fclose(g_cyc);
    if (state != cpu_Done) {
        fprintf(stderr, "firmware did not finish cleanly (state %d, cycle %llu)\n", state,
                (unsigned long long)avr->cycle);
        return 1;
    }
    return 0;
}
