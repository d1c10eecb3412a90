// Verilator harness of the Bayesian machine: streams pixels in on stdin, results out on stdout.
//
// Everything that depends on the design (widths, port names, lane and entropy offsets) comes
// from "design.h", which bayesmachine.sim.verilator.codegen generates from the Amaranth layouts;
// the code shared with the StereoMachine's harness (stereo.cpp) is in "common.h".
// Results go back as raw payloads: Python decodes them with the result layout (one decoder).
//
// Protocol (little-endian, binary), one batch per request, repeated until EOF or QUIT:
//   in : uint32 magic 'BMRN', uint32 flags (bit 0: drop the random numbers left over from earlier
//        batches), uint64 pixels; then per pixel its WORDS_PER_PIXEL uint16 likelihood words in
//        operator order and, if the design has a neighbour prior (BM_LINE_START 1), one uint16
//        line_start flag (0 or 1; set in every load beat of the pixel at LINE_START_OFFSET). The
//        whole batch is read before it runs.
//   out: uint64 message, one of
//        0 DONE: pixels * RESULT_WORDS uint32 raw result payloads, then uint64 wall cycles of this
//          batch, uint64 wall cycles since reset; the batch is over.
//        2 NEED NUMBERS (rng off chip only): uint64 rows wanted; the client replies on stdin with
//          uint64 rows n (0 < n <= wanted, or 0: no more), then n * ENTROPY_NUMBERS uint16 numbers,
//          one row per compute cycle (a number per operator and sample, sample-major). Rows not used by this batch stay for the next one.
//        1 RAN OUT: the client had no more numbers; the simulation is abandoned and the process exits.
// Output is written only while the client waits for it (after it wrote the whole batch), so
// neither side can block on a full pipe.
//
// Command line: harness [--trace PATH FIRST LAST] [--stall LOAD RESULT SEED]
//   --trace: dump waveforms while pixels FIRST..LAST, counted from reset across batches, are in
//            flight (needs a traced build).
//   --stall: drop load.valid / result.ready in a cycle with probability LOAD / RESULT per mille
//            (xorshift64 pattern from SEED); result stalls need a build whose top does not tie
//            result.ready high (BM_READY_TIED 0).

#include <cinttypes>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "design.h"
#include "common.h"
#if BM_TRACE == 1
#include "verilated_vcd_c.h"
typedef VerilatedVcdC TraceFile;
#elif BM_TRACE == 2
#include "verilated_fst_c.h"
typedef VerilatedFstC TraceFile;
#endif

static const uint32_t MAGIC_RUN = 0x4e524d42;  // "BMRN"

// Pseudo-random stalls: xorshift64, one draw per stream per cycle.
struct Stalls {
    uint64_t state = 0;
    unsigned load = 0, result = 0;  // per mille
    bool draw(unsigned permille) {
        if (!permille) return false;
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        return state % 1000 < permille;
    }
};

int main(int argc, char** argv) {
    const char* trace_path = nullptr;
    uint64_t trace_first = 0, trace_last = 0;
    Stalls stalls;
    for (int i = 1; i < argc; ++i) {
        if (!std::strcmp(argv[i], "--trace") && i + 3 < argc) {
            trace_path = argv[i + 1];
            trace_first = std::strtoull(argv[i + 2], nullptr, 10);
            trace_last = std::strtoull(argv[i + 3], nullptr, 10);
            i += 3;
        } else if (!std::strcmp(argv[i], "--stall") && i + 3 < argc) {
            stalls.load = static_cast<unsigned>(std::strtoul(argv[i + 1], nullptr, 10));
            stalls.result = static_cast<unsigned>(std::strtoul(argv[i + 2], nullptr, 10));
            stalls.state = std::strtoull(argv[i + 3], nullptr, 10) * 0x9e3779b97f4a7c15ull + 1;
            if (stalls.load >= 1000 || stalls.result >= 1000) fail("stall rates are per mille, below 1000");
            i += 3;
        } else {
            fail("usage: harness [--trace PATH FIRST_PIXEL LAST_PIXEL] [--stall LOAD RESULT SEED]");
        }
    }
    buffer_stdio();

    auto ctx = std::make_unique<VerilatedContext>();
    auto top = std::make_unique<BM_TOP>(ctx.get());
#if BM_TRACE
    std::unique_ptr<TraceFile> tfp;
    if (trace_path) {
        ctx->traceEverOn(true);
        tfp = std::make_unique<TraceFile>();
        top->trace(tfp.get(), 99);
        tfp->open(trace_path);
    }
#else
    if (trace_path) fail("this build has no waveform support (build with a trace)");
#endif
    // Random stalls lengthen the quiet stretches: allow 64 / (1 - p) cycles more than the watchdog,
    // as p^(64 / (1 - p)) < e^-64 makes that many stalls in a row a false alarm that never happens.
    const unsigned worst = stalls.load > stalls.result ? stalls.load : stalls.result;
    const uint64_t hang_cycles = HANG_CYCLES + (worst ? 64ull * 1000 / (1000 - worst) : 0);
    bool tracing = false;
    uint64_t wall_total = 0;  // clock cycles since reset

    top->BM_PORT_RESULT_READY = 0;
    top->BM_PORT_LOAD_VALID = 0;
    reset_design(*top);

    // A pixel's record in a request: its words, then its line_start flag (neighbour prior only).
    const unsigned record = WORDS_PER_PIXEL + BM_LINE_START;
    std::vector<uint16_t> words;
    std::vector<uint32_t> beats(static_cast<std::size_t>(BEATS_PER_PIXEL) * (LOAD_WORDS + 1));
    std::vector<uint32_t> records;
    uint64_t pixel_base = 0;  // global index of the batch's first pixel
    EntropySupply supply;  // rows of random numbers received and not yet used (off-chip sources)

    for (;;) {
        uint32_t head[4];
        if (!read_request(head, MAGIC_RUN)) break;
        const uint32_t flags = head[1];
        const uint64_t pixels = head[2] | (static_cast<uint64_t>(head[3]) << 32);
        words.resize(pixels * record);
        read_exact(words.data(), words.size() * sizeof(uint16_t));
        records.assign(pixels * RESULT_WORDS, 0);
        if (flags & 1) supply.clear();

        uint64_t loaded = 0, collected = 0, cycles = 0, idle = 0;
        unsigned beat = 0;
        auto pack = [&]() {  // the next pixel's words as load beats
            std::fill(beats.begin(), beats.end(), 0u);
            const uint16_t* px = &words[loaded * record];
            for (unsigned o = 0; o < WORDS_PER_PIXEL; ++o) {
                if (px[o] > WORD_ONE) fail("likelihood word out of range");
                put_bits(&beats[(o / LANES) * (LOAD_WORDS + 1)], LANE_OFFSET[o % LANES], LANE_BITS, px[o]);
            }
#if BM_LINE_START
            // The machine reads the flag with the pixel's last beat; every beat carries it.
            if (px[WORDS_PER_PIXEL] > 1) fail("line_start flag out of range");
            for (unsigned b = 0; b < BEATS_PER_PIXEL; ++b)
                put_bits(&beats[b * (LOAD_WORDS + 1)], LINE_START_OFFSET, 1, px[WORDS_PER_PIXEL]);
#endif
        };
        if (pixels) pack();
        while (collected < pixels) {
            const bool valid = loaded < pixels && !stalls.draw(stalls.load);
            top->BM_PORT_LOAD_VALID = valid;
            if (valid) set_port(top->BM_PORT_LOAD_PAYLOAD, &beats[beat * (LOAD_WORDS + 1)]);
#if BM_READY_TIED
            const bool ready = true;  // the top ties result.ready high; the port is unused
#else
            const bool ready = !stalls.draw(stalls.result);
#endif
            top->BM_PORT_RESULT_READY = ready;
            clock_low(*top, supply);
            const bool load_fire = valid && top->BM_PORT_LOAD_READY;
            const bool result_fire = ready && top->BM_PORT_RESULT_VALID;
#if BM_TRACE
            if (tfp) {
                // In flight: from the first beat of pixel FIRST to the result of pixel LAST.
                const uint64_t started = pixel_base + loaded + (valid ? 1 : 0);
                tracing = started > trace_first && pixel_base + collected <= trace_last;
                if (tracing) tfp->dump(2 * wall_total);
            }
#endif
            if (result_fire) take_result(top->BM_PORT_RESULT_PAYLOAD, &records[collected++ * RESULT_WORDS]);
            top->BM_PORT_CLK = 1;
            top->eval();
#if BM_TRACE
            if (tracing) tfp->dump(2 * wall_total + 1);
#endif
            ++cycles;
            ++wall_total;
            if (load_fire) {
                if (++beat == BEATS_PER_PIXEL) {
                    beat = 0;
                    if (++loaded < pixels) pack();
                }
            }
            // A design that neither takes a beat nor hands out a result for longer than the
            // watchdog allows is hung: stop with an error instead of spinning forever.
            idle = (load_fire || result_fire) ? 0 : idle + 1;
            if (idle > hang_cycles) fail("the design made no progress (no load beat, no result)");
        }
#if BM_TRACE
        if (tfp) tfp->flush();
#endif
        pixel_base += pixels;
        activity_write(*ctx);  // the toggles since the harness started (an activity build)
        send_results(records, cycles, wall_total);
    }
#if BM_TRACE
    if (tfp) tfp->close();
#endif
    top->final();
    return 0;
}
