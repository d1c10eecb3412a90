// Verilator harness of the Bayesian machine: streams pixels in on stdin, results out on stdout.
//
// Everything that depends on the design (widths, port names, result field offsets) comes from
// "design.h", which sim/verilator.py generates from the Amaranth layouts next to this file.
//
// Protocol (little-endian, binary), one batch per request, repeated until EOF or QUIT:
//   in : uint32 magic 'BMRN', uint32 reserved, uint64 pixels, uint64 numbers; then (rng =
//        "external" only) numbers * OPERATORS uint16 random numbers, one row per compute cycle;
//        then pixels * WORDS_PER_PIXEL uint16 likelihood words in operator order.
//   out: uint64 status (0 ok, 1 the random numbers ran out: no records follow, the simulation
//        is abandoned and the process exits), then pixels records of uint32[RECORD_WORDS] =
//        {map, nomatch, timeout, cycles, counts[ROWS]}, then uint64 wall cycles of this batch,
//        uint64 wall cycles since reset.
// Input is read lazily while the design runs; output is written once the batch is done, so a
// client that writes the whole batch before reading cannot deadlock on full pipes.
//
// Command line: harness [--trace PATH FIRST LAST]  (dump waveforms while pixels FIRST..LAST,
// counted from reset across batches, are in flight; needs a traced build).

#include <cinttypes>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "design.h"
#include "verilated.h"
#if BM_TRACE == 1
#include "verilated_vcd_c.h"
typedef VerilatedVcdC TraceFile;
#elif BM_TRACE == 2
#include "verilated_fst_c.h"
typedef VerilatedFstC TraceFile;
#endif

static const uint32_t MAGIC_RUN = 0x4e524d42;   // "BMRN"
static const uint32_t MAGIC_QUIT = 0x54514d42;  // "BMQT"

[[noreturn]] static void fail(const char* what) {
    std::fprintf(stderr, "bayesmachine harness: %s\n", what);
    std::exit(1);
}

// Ports narrower than 65 bits are plain integers in Verilator, wider ones VlWide<N>: overloads
// copy between either and a little-endian uint32 buffer.
static inline void set_port(CData& p, const uint32_t* w) { p = static_cast<CData>(w[0]); }
static inline void set_port(SData& p, const uint32_t* w) { p = static_cast<SData>(w[0]); }
static inline void set_port(IData& p, const uint32_t* w) { p = w[0]; }
static inline void set_port(QData& p, const uint32_t* w) { p = w[0] | (static_cast<QData>(w[1]) << 32); }
template <std::size_t N>
static inline void set_port(VlWide<N>& p, const uint32_t* w) {
    for (std::size_t i = 0; i < N; ++i) p[i] = w[i];
}
static inline void get_port(CData p, uint32_t* w) { w[0] = p; }
static inline void get_port(SData p, uint32_t* w) { w[0] = p; }
static inline void get_port(IData p, uint32_t* w) { w[0] = p; }
static inline void get_port(QData p, uint32_t* w) {
    w[0] = static_cast<uint32_t>(p);
    w[1] = static_cast<uint32_t>(p >> 32);
}
template <std::size_t N>
static inline void get_port(const VlWide<N>& p, uint32_t* w) {
    for (std::size_t i = 0; i < N; ++i) w[i] = p[i];
}

// Bits [offset, offset + width) of a little-endian uint32 buffer (width <= 32; the buffer has a
// spare word at the end so the two-word read never runs off it).
static inline uint32_t get_bits(const uint32_t* w, unsigned offset, unsigned width) {
    const unsigned i = offset >> 5, s = offset & 31;
    const uint64_t v = (w[i] | (static_cast<uint64_t>(w[i + 1]) << 32)) >> s;
    return static_cast<uint32_t>(v & ((width >= 32) ? 0xffffffffull : ((1ull << width) - 1)));
}
static inline void put_bits(uint32_t* w, unsigned offset, unsigned width, uint32_t value) {
    const unsigned i = offset >> 5, s = offset & 31;
    const uint64_t v = static_cast<uint64_t>(value) << s;
    w[i] |= static_cast<uint32_t>(v);
    if (s + width > 32) w[i + 1] |= static_cast<uint32_t>(v >> 32);
}

static void read_exact(void* buf, std::size_t bytes) {
    if (std::fread(buf, 1, bytes, stdin) != bytes) fail("input ended in the middle of a batch");
}

int main(int argc, char** argv) {
    const char* trace_path = nullptr;
    uint64_t trace_first = 0, trace_last = 0;
    for (int i = 1; i < argc; ++i) {
        if (!std::strcmp(argv[i], "--trace") && i + 3 < argc) {
            trace_path = argv[i + 1];
            trace_first = std::strtoull(argv[i + 2], nullptr, 10);
            trace_last = std::strtoull(argv[i + 3], nullptr, 10);
            i += 3;
        } else {
            fail("usage: harness [--trace PATH FIRST_PIXEL LAST_PIXEL]");
        }
    }
    static char inbuf[1 << 20], outbuf[1 << 20];
    std::setvbuf(stdin, inbuf, _IOFBF, sizeof inbuf);
    std::setvbuf(stdout, outbuf, _IOFBF, sizeof outbuf);

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
    bool tracing = false;
    uint64_t wall_total = 0;  // clock cycles since reset

    // Sync reset, held for a few cycles so registered resets inside the design settle too.
    top->BM_PORT_RESULT_READY = 0;
    top->BM_PORT_LOAD_VALID = 0;
    top->BM_PORT_RST = 1;
    for (int i = 0; i < 4; ++i) {
        top->BM_PORT_CLK = 0;
        top->eval();
        top->BM_PORT_CLK = 1;
        top->eval();
    }
    top->BM_PORT_RST = 0;
    for (int i = 0; i < 2; ++i) {  // the wrapper's registered reset is still high for a cycle
        top->BM_PORT_CLK = 0;
        top->eval();
        top->BM_PORT_CLK = 1;
        top->eval();
    }

    std::vector<uint16_t> words(WORDS_PER_PIXEL);
    std::vector<uint32_t> beats(static_cast<std::size_t>(BEATS_PER_PIXEL) * (LOAD_WORDS + 1));
    uint32_t result_buf[RESULT_WORDS + 1];
    std::vector<uint32_t> records;
    uint64_t pixel_base = 0;  // global index of the batch's first pixel

    for (;;) {
        uint32_t head[6];
        if (std::fread(head, 1, sizeof head, stdin) != sizeof head) break;  // EOF: client gone
        if (head[0] == MAGIC_QUIT) break;
        if (head[0] != MAGIC_RUN) fail("bad request header");
        const uint64_t pixels = head[2] | (static_cast<uint64_t>(head[3]) << 32);
        const uint64_t n_numbers = head[4] | (static_cast<uint64_t>(head[5]) << 32);
        records.assign(pixels * RECORD_WORDS, 0);
#if BM_EXTERNAL
        // The whole supply up front (words are then read lazily): one packed port value per row.
        std::vector<uint32_t> entropy(n_numbers * (ENTROPY_WORDS + 1), 0u);
        {
            std::vector<uint16_t> row(OPERATORS);
            for (uint64_t t = 0; t < n_numbers; ++t) {
                read_exact(row.data(), OPERATORS * sizeof(uint16_t));
                for (unsigned o = 0; o < OPERATORS; ++o)
                    put_bits(&entropy[t * (ENTROPY_WORDS + 1)], ENTROPY_OFFSET[o], ENTROPY_BITS, row[o]);
            }
        }
        uint64_t taken = 0;  // rows of random numbers consumed by compute cycles
#else
        if (n_numbers) fail("this machine has LFSRs: it takes no random numbers");
#endif

        uint64_t loaded = 0, collected = 0, cycles = 0, idle = 0;
        unsigned beat = 0;
        auto fetch = [&]() {  // read and pack the next pixel's words into load beats
            read_exact(words.data(), WORDS_PER_PIXEL * sizeof(uint16_t));
            std::fill(beats.begin(), beats.end(), 0u);
            for (unsigned o = 0; o < WORDS_PER_PIXEL; ++o) {
                if (words[o] > WORD_ONE) fail("likelihood word out of range");
                put_bits(&beats[(o / LANES) * (LOAD_WORDS + 1)], LANE_OFFSET[o % LANES], LANE_BITS,
                         words[o]);
            }
        };
        if (pixels) fetch();
        while (collected < pixels) {
            const bool valid = loaded < pixels;
            top->BM_PORT_LOAD_VALID = valid;
            if (valid) set_port(top->BM_PORT_LOAD_PAYLOAD, &beats[beat * (LOAD_WORDS + 1)]);
            top->BM_PORT_RESULT_READY = 1;
#if BM_EXTERNAL
            if (taken < n_numbers) set_port(top->BM_PORT_ENTROPY, &entropy[taken * (ENTROPY_WORDS + 1)]);
#endif
            top->BM_PORT_CLK = 0;
            top->eval();
            const bool load_fire = valid && top->BM_PORT_LOAD_READY;
            const bool result_fire = top->BM_PORT_RESULT_VALID;
#if BM_EXTERNAL
            if (top->BM_PORT_ENTROPY_READY) {
                if (taken == n_numbers) {
                    // A compute cycle with no number left: as the model, give up on the batch.
                    const uint64_t status = 1;
                    std::fwrite(&status, sizeof status, 1, stdout);
                    std::fflush(stdout);
                    std::fprintf(stderr, "bayesmachine harness: the random numbers ran out\n");
                    return 3;
                }
                ++taken;
            }
#endif
#if BM_TRACE
            if (tfp) {
                // In flight: from the first beat of pixel FIRST to the result of pixel LAST.
                const uint64_t started = pixel_base + loaded + (valid ? 1 : 0);
                tracing = started > trace_first && pixel_base + collected <= trace_last;
                if (tracing) tfp->dump(2 * wall_total);
            }
#endif
            if (result_fire) {
                std::memset(result_buf, 0, sizeof result_buf);
                get_port(top->BM_PORT_RESULT_PAYLOAD, result_buf);
                uint32_t* rec = &records[collected * RECORD_WORDS];
                rec[0] = get_bits(result_buf, MAP_OFFSET, MAP_WIDTH);
                rec[1] = get_bits(result_buf, NOMATCH_OFFSET, 1);
                rec[2] = get_bits(result_buf, TIMEOUT_OFFSET, 1);
                rec[3] = get_bits(result_buf, CYCLES_OFFSET, CYCLES_WIDTH);
                for (unsigned r = 0; r < ROWS; ++r)
                    rec[4 + r] = get_bits(result_buf, COUNT_OFFSET[r], COUNT_WIDTH);
                ++collected;
            }
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
                    if (++loaded < pixels) fetch();
                }
            }
            // A design that neither takes a beat nor hands out a result for longer than the
            // watchdog allows is hung: stop with an error instead of spinning forever.
            idle = (load_fire || result_fire) ? 0 : idle + 1;
            if (idle > HANG_CYCLES) fail("the design made no progress (no load beat, no result)");
        }
#if BM_TRACE
        if (tfp) tfp->flush();
#endif
        pixel_base += pixels;
        const uint64_t status = 0;
        std::fwrite(&status, sizeof status, 1, stdout);
        std::fwrite(records.data(), sizeof(uint32_t), records.size(), stdout);
        const uint64_t tail[2] = {cycles, wall_total};
        std::fwrite(tail, sizeof tail, 1, stdout);
        std::fflush(stdout);
    }
#if BM_TRACE
    if (tfp) tfp->close();
#endif
    top->final();
    return 0;
}
