/* QEMU TCG plugin (QEMU 7.2, plugin API version 1): counts every executed guest instruction
 * by its address, but only while counting is switched on. Executing the first instruction of
 * an address listed in PROF_ON switches it on, of one in PROF_OFF off (comma-separated hex).
 * At exit it writes "address count" lines for every address executed while on to PROF_OUT.
 *
 * scripts/tick-profile.sh builds it and switches on at the bench's TickMeter::tick and
 * TickMeter::leave, off at TickMeter::tick_start and TickMeter::enter: the instructions the
 * bench counts as the firmware's control tick.
 *
 * A tick begins at each execution of the first PROF_ON address. With PROF_TICKS set, the
 * instructions counted in each tick go to that file, one line a tick ("index count"); with
 * PROF_ONLY_TICK=N only tick N (from 0) is counted by address (the worst tick's profile).
 *
 * With PROF_HELPERS (comma-separated "start-end" hex ranges: the runtime's out-of-line helpers,
 * memcpy and the like) an instruction inside a helper is not counted at its own address but at
 * the last address executed outside the helpers: the call site (helpers are leaves, or call
 * only helpers). Those counts go to PROF_OUT as "address count H" lines, so the caller's crate
 * owns what its copies cost (attribute.py's `crates` mode).
 *
 * The few declarations of QEMU's plugin API used here are written out below (Debian's
 * qemu-system-arm ships plugin support but not <qemu-plugin.h>).
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef uint64_t qemu_plugin_id_t;
struct qemu_plugin_tb;
struct qemu_plugin_insn;
typedef struct qemu_info_t qemu_info_t;
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS };

__attribute__((visibility("default"))) int qemu_plugin_version = 1;

void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id,
                                           void (*cb)(qemu_plugin_id_t, struct qemu_plugin_tb *));
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn,
                                            void (*cb)(unsigned int, void *),
                                            enum qemu_plugin_cb_flags flags, void *userdata);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, void (*cb)(qemu_plugin_id_t, void *),
                                    void *userdata);

/* Code addresses below 16 MiB (the mps2 machines' flash/code region), two bytes apart. */
#define SLOTS (8u << 20)
#define MAX_MARKS 8

static uint64_t *counts;
static int on;
static uint64_t on_at[MAX_MARKS], off_at[MAX_MARKS];
static int n_on, n_off;
static const char *out_path = "tick-profile.txt";
static FILE *ticks_out;
static long only_tick = -1;
static long tick = -1;
static uint64_t in_tick;
#define MAX_HELPERS 64
static uint64_t helper_lo[MAX_HELPERS], helper_hi[MAX_HELPERS];
static int n_helpers;
static uint64_t *helper_counts;
static uint64_t last_own_pc;

static int in_helper(uint64_t pc) {
    for (int i = 0; i < n_helpers; i++)
        if (pc >= helper_lo[i] && pc < helper_hi[i]) return 1;
    return 0;
}

static void executed(unsigned int vcpu, void *udata) {
    uint64_t pc = (uintptr_t)udata;
    (void)vcpu;
    for (int i = 0; i < n_off; i++)
        if (pc == off_at[i]) on = 0;
    for (int i = 0; i < n_on; i++)
        if (pc == on_at[i]) on = 1;
    if (n_on > 0 && pc == on_at[0]) {
        if (ticks_out && tick >= 0) fprintf(ticks_out, "%ld %llu\n", tick, (unsigned long long)in_tick);
        tick++;
        in_tick = 0;
    }
    int helper = n_helpers > 0 && in_helper(pc);
    if (on) {
        in_tick++;
        if (only_tick < 0 || tick == only_tick) {
            if (helper)
                helper_counts[last_own_pc / 2]++;
            else
                counts[pc / 2]++;
        }
    }
    if (!helper) last_own_pc = pc;
}

static void translated(qemu_plugin_id_t id, struct qemu_plugin_tb *tb) {
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t pc = qemu_plugin_insn_vaddr(insn);
        if (pc / 2 < SLOTS)
            qemu_plugin_register_vcpu_insn_exec_cb(insn, executed, QEMU_PLUGIN_CB_NO_REGS,
                                                   (void *)(uintptr_t)pc);
    }
}

static void finished(qemu_plugin_id_t id, void *udata) {
    (void)id;
    (void)udata;
    if (ticks_out) {
        if (tick >= 0) fprintf(ticks_out, "%ld %llu\n", tick, (unsigned long long)in_tick);
        fclose(ticks_out);
    }
    FILE *f = fopen(out_path, "w");
    if (!f) return;
    for (uint64_t i = 0; i < SLOTS; i++)
        if (counts[i]) fprintf(f, "%llx %llu\n", (unsigned long long)(i * 2),
                               (unsigned long long)counts[i]);
    for (uint64_t i = 0; i < SLOTS; i++)
        if (helper_counts && helper_counts[i])
            fprintf(f, "%llx %llu H\n", (unsigned long long)(i * 2),
                    (unsigned long long)helper_counts[i]);
    fclose(f);
}

static int marks(const char *env, uint64_t *at) {
    const char *s = getenv(env);
    int n = 0;
    char buf[512];
    if (!s) return 0;
    strncpy(buf, s, sizeof buf - 1);
    buf[sizeof buf - 1] = 0;
    for (char *t = strtok(buf, ","); t && n < MAX_MARKS; t = strtok(NULL, ","))
        at[n++] = strtoull(t, NULL, 16) & ~1ull; /* Thumb: the bit-0 of a symbol is not the pc */
    return n;
}

__attribute__((visibility("default"))) int qemu_plugin_install(qemu_plugin_id_t id,
                                                               const qemu_info_t *info,
                                                               int argc, char **argv) {
    (void)info;
    (void)argc;
    (void)argv;
    counts = calloc(SLOTS, sizeof *counts);
    if (!counts) return -1;
    const char *o = getenv("PROF_OUT");
    if (o) out_path = o;
    const char *t = getenv("PROF_TICKS");
    if (t) ticks_out = fopen(t, "w");
    const char *only = getenv("PROF_ONLY_TICK");
    if (only) only_tick = strtol(only, NULL, 10);
    n_on = marks("PROF_ON", on_at);
    n_off = marks("PROF_OFF", off_at);
    const char *h = getenv("PROF_HELPERS");
    if (h && *h) {
        char hb[4096];
        strncpy(hb, h, sizeof hb - 1);
        hb[sizeof hb - 1] = 0;
        if (strlen(h) >= sizeof hb)
            fprintf(stderr, "gate: PROF_HELPERS longer than %zu bytes: the rest ignored\n",
                    sizeof hb - 1);
        for (char *t = strtok(hb, ","); t; t = strtok(NULL, ",")) {
            char *dash = strchr(t, '-');
            if (!dash) continue;
            if (n_helpers == MAX_HELPERS) {
                /* The rest count at their own address (attribute.py: "other", the loop). */
                fprintf(stderr, "gate: more than %d helper ranges: the rest not attributed\n",
                        MAX_HELPERS);
                break;
            }
            helper_lo[n_helpers] = strtoull(t, NULL, 16) & ~1ull;
            helper_hi[n_helpers] = strtoull(dash + 1, NULL, 16) & ~1ull;
            n_helpers++;
        }
        helper_counts = calloc(SLOTS, sizeof *helper_counts);
        if (!helper_counts) return -1;
    }
    if (n_on == 0) on = 1; /* no marks: count everything */
    qemu_plugin_register_vcpu_tb_trans_cb(id, translated);
    qemu_plugin_register_atexit_cb(id, finished, NULL);
    return 0;
}
