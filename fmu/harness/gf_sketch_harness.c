/*
 * gf_sketch_harness: run the Arduino sketch of grasprom (built with arduino-mk) under libsimavr,
 * drive its inputs from a script and record what a bench would measure.
 *
 * Usage: gf_sketch_harness FIRMWARE.elf SCRIPT OUTDIR SCOPE_PORT SCOPE_BIT
 *
 * SCRIPT: one action per line, "<t_ms> <action> [args]", times ascending:
 *   <t> enc <raw>          the quadrature encoder moves linearly to raw count <raw> by t
 *                          (one valid transition per 10 us at most; pins PD2 = A, PD3 = B)
 *   <t> pin <P><bit> <0|1> drive an input pin, e.g. "pin D4 0"
 *   <t> send <text>        send <text> and '\n' on USART0 (one byte per 90 us)
 *   <t> flash <addr> <v>   overwrite one flash byte (a corrupted table)
 *   <t> glitch             both encoder channels change at once (an invalid transition)
 *   <t> end                stop
 * OUTDIR/uart.log    serial output, one line per text line: "<cycle>\t<text>"
 * OUTDIR/samples.csv every 250 us: cycle, the harness's raw encoder count and the registers of Timer1, Timer2, the watchdog and
 *                    ports B, C, D (data-space values)
 * OUTDIR/resets.txt cycle of every reset of the MCU after the first (the watchdog)
 * OUTDIR/scope.txt   rising and falling cycles of the scope pin (the control step), one pair
 *                    per line
 * Exit status 0 when the script ran to its end, 1 if the firmware crashed, 2 on usage errors.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/avr_ioport.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>
#include <simavr/sim_cycle_timers.h>

#define F_CPU 16000000ULL
#define MAX_ACTIONS 4096
#define ENC_DT 160ULL     /* cycles between encoder transitions (10 us) */
#define SAMPLE_DT 4000ULL /* cycles between register samples (250 us) */
#define UART_DT 1440ULL   /* cycles between sent bytes (90 us, > 1 byte at 115200 baud) */

typedef struct {
    unsigned long long cycle;
    char kind[8];
    long a, b;
    char port;
    char text[96];
} action_t;

static action_t g_act[MAX_ACTIONS];
static int g_n, g_next;
static avr_t *g_avr;
static FILE *g_uart, *g_samples, *g_scope, *g_resets;
static void (*g_mcu_reset)(struct avr_t *avr);
static int g_was_reset;
static int g_uart_bol = 1;
static unsigned long long g_scope_rise;
/* encoder: waypoints (cycle, raw), starting at (0, 0), and the current position */
static unsigned long long g_wc[MAX_ACTIONS + 1];
static long g_wv[MAX_ACTIONS + 1];
static int g_nw = 1, g_iw;
static long g_pos;
static avr_irq_t *g_uart_in;
/* bytes to send */
static char g_tx[4096];
static int g_tx_head, g_tx_tail;

static const uint8_t SEQ[4] = {0, 2, 3, 1}; /* (B << 1 | A) at raw positions 0..3 mod 4 */

/* Drive an input pin from outside: the level is also declared "external" to simavr, so the
 * sketch's pull-ups do not override it when it writes the port register. */
static uint8_t g_ext_mask[3], g_ext_value[3]; /* ports B, C, D */

static void drive_pin(char port, int bit, int level) {
    avr_ioport_external_t e;
    int i = port - 'B';
    g_ext_mask[i] |= (uint8_t)(1u << bit);
    if (level) g_ext_value[i] |= (uint8_t)(1u << bit);
    else g_ext_value[i] &= (uint8_t)~(1u << bit);
    e.name = (unsigned)port;
    e.mask = g_ext_mask[i];
    e.value = g_ext_value[i];
    avr_ioctl(g_avr, AVR_IOCTL_IOPORT_SET_EXTERNAL(port), &e);
    avr_raise_irq(avr_io_getirq(g_avr, AVR_IOCTL_IOPORT_GETIRQ(port), bit), (uint32_t)level);
}

static int g_ab = -1; /* the levels last driven on A/B */

static void set_ab(uint8_t ab) { /* ab = B << 1 | A, as the sketch reads (PIND >> 2) & 3 */
    if (g_ab < 0 || ((g_ab ^ ab) & 1u)) drive_pin('D', 2, ab & 1u);
    if (g_ab < 0 || ((g_ab ^ ab) & 2u)) drive_pin('D', 3, (ab >> 1) & 1u);
    g_ab = ab;
}

static void on_uart(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq; (void)param;
    if (g_uart_bol) { fprintf(g_uart, "%llu\t", (unsigned long long)g_avr->cycle); g_uart_bol = 0; }
    if (value == '\r') return;
    fputc((int)value, g_uart);
    if (value == '\n') g_uart_bol = 1;
}

static void on_scope(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq; (void)param;
    if (value) g_scope_rise = g_avr->cycle;
    else if (g_scope_rise) fprintf(g_scope, "%llu %llu\n", g_scope_rise, (unsigned long long)g_avr->cycle);
}

static void on_reset(struct avr_t *avr) { /* avr_reset() calls it: a reset witnessed */
    fprintf(g_resets, "%llu\n", (unsigned long long)avr->cycle);
    g_was_reset = 1; /* avr_reset() drops the cycle timers: registered again after it */
    if (g_mcu_reset) g_mcu_reset(avr);
}

static unsigned rd8(unsigned addr) { return g_avr->data[addr]; }
static unsigned rd16(unsigned lo) { return g_avr->data[lo] | (g_avr->data[lo + 1] << 8); }

static avr_cycle_count_t on_sample(avr_t *avr, avr_cycle_count_t when, void *param) {
    (void)param;
    /* TCCR1A 0x80, TCCR1B 0x81, ICR1 0x86, OCR1A 0x88, OCR1B 0x8A, TCCR2A 0xB0, TCCR2B 0xB1,
     * OCR2A 0xB3, TIMSK2 0x70, WDTCSR 0x60, PORTB 0x25, DDRB 0x24, PORTC 0x28, PORTD 0x2B,
     * DDRD 0x2A */
    fprintf(g_samples, "%llu,%ld,%u,%u,%u,%u,%u,%u,%u,%u,%u,%u,%u,%u,%u,%u,%u\n",
            (unsigned long long)avr->cycle, g_pos, rd8(0x80), rd8(0x81), rd16(0x86), rd16(0x88),
            rd16(0x8A), rd8(0xB0), rd8(0xB1), rd8(0xB3), rd8(0x70), rd8(0x60), rd8(0x25),
            rd8(0x24), rd8(0x28), rd8(0x2B), rd8(0x2A));
    return when + SAMPLE_DT;
}

static avr_cycle_count_t on_encoder(avr_t *avr, avr_cycle_count_t when, void *param) {
    long target;
    (void)param;
    while (g_iw + 1 < g_nw && g_wc[g_iw + 1] <= avr->cycle) ++g_iw;
    if (g_iw + 1 >= g_nw) target = g_wv[g_iw];
    else target = g_wv[g_iw] + (long)((double)(g_wv[g_iw + 1] - g_wv[g_iw]) *
                                      (double)(avr->cycle - g_wc[g_iw]) /
                                      (double)(g_wc[g_iw + 1] - g_wc[g_iw]));
    if (target != g_pos) g_pos += target > g_pos ? 1 : -1;
    set_ab(SEQ[((g_pos % 4) + 4) % 4]);
    return when + ENC_DT;
}

static avr_cycle_count_t on_tx(avr_t *avr, avr_cycle_count_t when, void *param) {
    (void)avr; (void)param;
    if (g_tx_head != g_tx_tail) {
        avr_raise_irq(g_uart_in, (uint8_t)g_tx[g_tx_tail]);
        g_tx_tail = (g_tx_tail + 1) % (int)sizeof g_tx;
    }
    return when + UART_DT;
}

static void start_timers(void) {
    avr_cycle_timer_register(g_avr, SAMPLE_DT, on_sample, NULL);
    avr_cycle_timer_register(g_avr, ENC_DT, on_encoder, NULL);
    avr_cycle_timer_register(g_avr, UART_DT, on_tx, NULL);
}

static void queue_text(const char *s) {
    for (; *s; ++s) { g_tx[g_tx_head] = *s; g_tx_head = (g_tx_head + 1) % (int)sizeof g_tx; }
    g_tx[g_tx_head] = '\n';
    g_tx_head = (g_tx_head + 1) % (int)sizeof g_tx;
}

static int load_script(const char *path) {
    FILE *f = fopen(path, "r");
    char buf[160];
    if (!f) { fprintf(stderr, "cannot read %s\n", path); return -1; }
    while (fgets(buf, sizeof buf, f)) {
        action_t *a;
        double t;
        int used = 0;
        if (buf[0] == '#' || buf[0] == '\n') continue;
        if (g_n >= MAX_ACTIONS) { fprintf(stderr, "script too long\n"); fclose(f); return -1; }
        a = &g_act[g_n];
        memset(a, 0, sizeof *a);
        if (sscanf(buf, "%lf %7s %n", &t, a->kind, &used) < 2) {
            fprintf(stderr, "bad script line: %s", buf);
            fclose(f);
            return -1;
        }
        a->cycle = (unsigned long long)(t * 1e-3 * (double)F_CPU + 0.5);
        if (strcmp(a->kind, "enc") == 0) {
            a->a = strtol(buf + used, NULL, 10);
            g_wc[g_nw] = a->cycle;
            g_wv[g_nw++] = a->a;
        }
        else if (strcmp(a->kind, "pin") == 0) {
            a->port = buf[used];
            a->a = strtol(buf + used + 1, NULL, 10);
            a->b = strtol(buf + used + 3, NULL, 10);
            if (a->port < 'B' || a->port > 'D' || a->a < 0 || a->a > 7) {
                fprintf(stderr, "bad pin (ports B, C, D, bits 0-7): %s", buf);
                fclose(f);
                return -1;
            }
        } else if (strcmp(a->kind, "flash") == 0) {
            char *e;
            a->a = strtol(buf + used, &e, 0);
            a->b = strtol(e, NULL, 0);
        } else if (strcmp(a->kind, "send") == 0) {
            size_t n;
            strncpy(a->text, buf + used, sizeof a->text - 1);
            n = strlen(a->text);
            while (n && (a->text[n - 1] == '\n' || a->text[n - 1] == '\r')) a->text[--n] = '\0';
        } else if (strcmp(a->kind, "glitch") != 0 && strcmp(a->kind, "end") != 0) {
            fprintf(stderr, "unknown action %s\n", a->kind);
            fclose(f);
            return -1;
        }
        ++g_n;
    }
    fclose(f);
    return 0;
}

static void apply(const action_t *a) {
    if (strcmp(a->kind, "pin") == 0) {
        drive_pin(a->port, (int)a->a, (int)a->b);
    } else if (strcmp(a->kind, "send") == 0) {
        queue_text(a->text);
    } else if (strcmp(a->kind, "flash") == 0) {
        if (a->a >= 0 && (uint32_t)a->a <= g_avr->flashend) g_avr->flash[a->a] = (uint8_t)a->b;
    } else if (strcmp(a->kind, "glitch") == 0) {
        uint8_t ab = SEQ[((g_pos % 4) + 4) % 4];
        long k;
        set_ab((uint8_t)(ab ^ 3u));
        g_pos += 2; /* the position two transitions on: later moves stay valid */
        for (k = 0; k < g_nw; ++k) g_wv[k] += 2;
    }
}

int main(int argc, char **argv) {
    elf_firmware_t fw;
    char path[1024];
    int state = cpu_Running;
    unsigned long long end = 0;
    uint32_t flags = 0;
    int i;
    if (argc != 6) {
        fprintf(stderr, "usage: %s FIRMWARE.elf SCRIPT OUTDIR SCOPE_PORT SCOPE_BIT\n", argv[0]);
        return 2;
    }
    if (load_script(argv[2]) != 0) return 2;
    for (i = 0; i < g_n; ++i) if (strcmp(g_act[i].kind, "end") == 0) end = g_act[i].cycle;
    if (!end) { fprintf(stderr, "the script has no 'end'\n"); return 2; }
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(argv[1], &fw) != 0) { fprintf(stderr, "cannot read %s\n", argv[1]); return 2; }
    g_avr = avr_make_mcu_by_name("atmega328p");
    if (!g_avr) { fprintf(stderr, "no atmega328p in this simavr\n"); return 2; }
    avr_init(g_avr);
    g_avr->log = 0;
    fw.frequency = (uint32_t)F_CPU;
    avr_load_firmware(g_avr, &fw);
    g_mcu_reset = g_avr->reset;
    g_avr->reset = on_reset;
    snprintf(path, sizeof path, "%s/uart.log", argv[3]);
    g_uart = fopen(path, "w");
    snprintf(path, sizeof path, "%s/samples.csv", argv[3]);
    g_samples = fopen(path, "w");
    snprintf(path, sizeof path, "%s/scope.txt", argv[3]);
    g_scope = fopen(path, "w");
    snprintf(path, sizeof path, "%s/resets.txt", argv[3]);
    g_resets = fopen(path, "w");
    if (!g_uart || !g_samples || !g_scope || !g_resets) { fprintf(stderr, "cannot write to %s\n", argv[3]); return 2; }
    fprintf(g_samples, "cycle,encoder,TCCR1A,TCCR1B,ICR1,OCR1A,OCR1B,TCCR2A,TCCR2B,OCR2A,TIMSK2,WDTCSR,"
                       "PORTB,DDRB,PORTC,PORTD,DDRD\n");
    avr_ioctl(g_avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(uint32_t)AVR_UART_FLAG_STDIO;
    avr_ioctl(g_avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_irq_register_notify(avr_io_getirq(g_avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            on_uart, NULL);
    g_uart_in = avr_io_getirq(g_avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(g_avr, AVR_IOCTL_IOPORT_GETIRQ(argv[4][0]), atoi(argv[5])),
                            on_scope, NULL);
    set_ab(SEQ[0]);
    start_timers();
    g_next = 0;
    while (g_avr->cycle < end) {
        while (g_next < g_n && g_act[g_next].cycle <= g_avr->cycle) apply(&g_act[g_next++]);
        state = avr_run(g_avr);
        if (g_was_reset) {
            int pt, bt;
            g_was_reset = 0;
            start_timers();
            for (pt = 0; pt < 3; ++pt) /* the outside world keeps its levels over a reset */
                for (bt = 0; bt < 8; ++bt)
                    if (g_ext_mask[pt] >> bt & 1u) { /* toggled: an unchanged value is filtered */
                        int v = g_ext_value[pt] >> bt & 1u;
                        drive_pin((char)('B' + pt), bt, !v);
                        drive_pin((char)('B' + pt), bt, v);
                    }
        }
        if (state == cpu_Crashed) break;
        if (state == cpu_Done) break;
    }
    fclose(g_uart);
    fclose(g_samples);
    fclose(g_scope);
    fclose(g_resets);
    if (state == cpu_Crashed) {
        fprintf(stderr, "firmware crashed at cycle %llu\n", (unsigned long long)g_avr->cycle);
        return 1;
    }
    return 0;
}
