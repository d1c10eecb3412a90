// What the Verilator harnesses share (harness.cpp: the machine, stereo.cpp: the StereoMachine):
// errors, copying between ports and little-endian uint32 buffers, the pipe protocol's framing,
// the reset sequence and the reply with the raw result payloads (Python decodes them with the
// result layout: one decoder).
//
// Include it after the generated header, which defines BM_TOP, BM_PORT_CLK, BM_PORT_RST,
// RESULT_WORDS, HANG_CYCLES and BM_EXTERNAL (with an off-chip random source, 1, and the entropy
// port's BM_PORT_ENTROPY, BM_PORT_ENTROPY_READY, ENTROPY_NUMBERS, ENTROPY_BITS, ENTROPY_WORDS,
// ENTROPY_OFFSET: the design's entropy port is fed by EntropySupply below, the same way in
// every harness).
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <utility>
#include <vector>

#include "verilated.h"

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

// Sets bits [offset, offset + width) of a little-endian uint32 buffer (width <= 32; the buffer has
// a spare word at the end so the two-word write never runs off it).
static inline void put_bits(uint32_t* w, unsigned offset, unsigned width, uint32_t value) {
    const unsigned i = offset >> 5, s = offset & 31;
    const uint64_t v = static_cast<uint64_t>(value) << s;
    w[i] |= static_cast<uint32_t>(v);
    if (s + width > 32) w[i + 1] |= static_cast<uint32_t>(v >> 32);
}

static void read_exact(void* buf, std::size_t bytes) {
    if (std::fread(buf, 1, bytes, stdin) != bytes) fail("input ended in the middle of a request");
}

static void put_u64(uint64_t v) {
    if (std::fwrite(&v, sizeof v, 1, stdout) != 1) fail("cannot write to the client");
}

// Large stdio buffers: requests and replies are big binary blocks.
static void buffer_stdio() {
    static char inbuf[1 << 20], outbuf[1 << 20];
    std::setvbuf(stdin, inbuf, _IOFBF, sizeof inbuf);
    std::setvbuf(stdout, outbuf, _IOFBF, sizeof outbuf);
}

// The next request's 16-byte header into head; false at EOF (the client is gone) or QUIT.
static bool read_request(uint32_t head[4], uint32_t magic) {
    if (std::fread(head, 1, 4 * sizeof(uint32_t), stdin) != 4 * sizeof(uint32_t)) return false;
    if (head[0] == MAGIC_QUIT) return false;
    if (head[0] != magic) fail("bad request header");
    return true;
}

static void tick(BM_TOP& top) {
    top.BM_PORT_CLK = 0;
    top.eval();
    top.BM_PORT_CLK = 1;
    top.eval();
}

// Switching activity (a build with --coverage-toggle, VM_COVERAGE): every signal bit's toggles
// counted by Verilator, written to the file named by the environment variable BM_ACTIVITY
// (bayesmachine.sim.activity reads it): the stereo harness's of each frame (zeroed when it starts),
// the machine's harness's since it started, after each request.
#if VM_COVERAGE
#include "verilated_cov.h"
static void activity_start(VerilatedContext& ctx) { ctx.coveragep()->zero(); }
static void activity_write(VerilatedContext& ctx) {
    const char* path = std::getenv("BM_ACTIVITY");
    if (path != nullptr) ctx.coveragep()->write(path);
}
#else
static void activity_start(VerilatedContext&) {}
static void activity_write(VerilatedContext&) {}
#endif

// Sync reset, held for a few cycles so registered resets inside the design settle too; the
// wrapper's registered reset is still high for a cycle after the port falls.
static void reset_design(BM_TOP& top) {
    top.BM_PORT_RST = 1;
    for (int i = 0; i < 4; ++i) tick(top);
    top.BM_PORT_RST = 0;
    for (int i = 0; i < 2; ++i) tick(top);
}

// The result payload on the port, as RESULT_WORDS uint32 words at record.
template <typename Port>
static inline void take_result(const Port& port, uint32_t* record) {
    uint32_t buf[RESULT_WORDS + 2] = {0};
    get_port(port, buf);
    std::memcpy(record, buf, RESULT_WORDS * sizeof(uint32_t));
}

// The DONE reply: uint64 0, the raw result payloads, uint64 wall cycles of this request, uint64
// wall cycles since reset.
static void send_results(const std::vector<uint32_t>& records, uint64_t cycles, uint64_t wall_total) {
    put_u64(0);
    if (std::fwrite(records.data(), sizeof(uint32_t), records.size(), stdout) != records.size())
        fail("cannot write to the client");
    put_u64(cycles);
    put_u64(wall_total);
    std::fflush(stdout);
}

#if BM_EXTERNAL
// The random numbers of an off-chip source, one row (a number per operator and sample: ENTROPY_NUMBERS)
// per compute cycle, asked from the client in blocks (message 2 NEED NUMBERS: uint64 2, uint64 rows
// wanted; the client replies uint64 rows n (0 < n <= wanted, or 0: no more), then n * ENTROPY_NUMBERS
// uint16).
// Rows received and not yet used stay for the next request.
struct EntropySupply {
    std::deque<std::vector<uint32_t>> rows;  // packed entropy port values
    std::vector<uint16_t> row = std::vector<uint16_t>(ENTROPY_NUMBERS);

    void clear() { rows.clear(); }

    // Asks the client for more rows; false if it has none left.
    bool refill() {
        put_u64(2);
        put_u64(4096);
        std::fflush(stdout);
        uint64_t n = 0;
        read_exact(&n, sizeof n);
        if (n > 4096) fail("the client sent more rows of random numbers than asked for");
        for (uint64_t t = 0; t < n; ++t) {
            read_exact(row.data(), ENTROPY_NUMBERS * sizeof(uint16_t));
            std::vector<uint32_t> packed(ENTROPY_WORDS + 1, 0u);
            for (unsigned o = 0; o < ENTROPY_NUMBERS; ++o) {
                if (row[o] >> ENTROPY_BITS) fail("random number out of range");
                put_bits(packed.data(), ENTROPY_OFFSET[o], ENTROPY_BITS, row[o]);
            }
            rows.push_back(std::move(packed));
        }
        return n > 0;
    }

    // Before the clock's first eval: the next row on the port.
    void present(BM_TOP& top) {
        if (!rows.empty()) set_port(top.BM_PORT_ENTROPY, rows.front().data());
    }

    // After it: a compute cycle (entropy_ready) consumes one row, asked for if none is left.
    // False when the client has no more.
    bool consume(BM_TOP& top) {
        if (!top.BM_PORT_ENTROPY_READY) return true;
        if (rows.empty()) {
            if (!refill()) return false;
            set_port(top.BM_PORT_ENTROPY, rows.front().data());
            top.eval();
        }
        rows.pop_front();
        return true;
    }
};

#else
// An on-chip source: no numbers to supply.
struct EntropySupply {
    void clear() {}
    void present(BM_TOP&) {}
    bool consume(BM_TOP&) { return true; }
};
#endif

// The RAN OUT reply: the client had no more numbers; the process ends.
[[noreturn]] static void ran_out() {
    put_u64(1);
    std::fflush(stdout);
    std::exit(3);
}

// The clock's low half, as every harness runs it (inputs already set): with an off-chip source
// the next row of numbers on the entropy port first, and after the evaluation a row consumed by
// a compute cycle; no number left: as in the model, the request is abandoned (RAN OUT).
static void clock_low(BM_TOP& top, EntropySupply& supply) {
    supply.present(top);
    top.BM_PORT_CLK = 0;
    top.eval();
    if (!supply.consume(top)) ran_out();
}
