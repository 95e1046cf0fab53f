// Steps/s of gng_collection's plain C++ GNG (nkys39/gng_collection, algorithms/gng/cpp/gng.hpp,
// GNG3f: one topology, positions only) on the 3-D points of a float32 file, for
// benchmarks/bench_core.py's optional C++ column. Not part of gngdt: build it outside the
// repository, against a checkout of gng_collection and Eigen 3:
//
//   git clone https://github.com/nkys39/gng_collection /tmp/gng_collection
//   g++ -O3 -march=native -DNDEBUG -std=c++17 -I/tmp/gng_collection/algorithms/gng/cpp \
//       -I/usr/include/eigen3 benchmarks/gng_cpp_driver.cpp -o /tmp/gng_driver
//   python benchmarks/bench_core.py --cpp /tmp/gng_driver
//
//   gng_driver POINTS.f32 FTZ NODES:STEPS [NODES:STEPS ...]
//
// For each NODES:STEPS: a GNG of NODES nodes at most grows on the points (lambda * NODES +
// 200,000 steps, samples drawn at random as GrowingNeuralGas::train draws them), then STEPS
// more steps are timed in thread CPU time. FTZ 1 flushes subnormal floats to zero, as a
// -ffast-math build does (the plain build's floats decaying toward an exact 0 of the data turn
// subnormal and cost ~100 cycles an operation); FTZ 0 is strict IEEE arithmetic.
// Prints one line per size: "nodes N steps S: R steps/s".
#include <pmmintrin.h>
#include <xmmintrin.h>

#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <string>
#include <vector>

#include "gng.hpp"

static double thread_seconds() {
    timespec now;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
    return now.tv_sec + 1e-9 * now.tv_nsec;
}

int main(int argc, char** argv) {
    if (argc < 4) {
        std::fprintf(stderr, "usage: %s POINTS.f32 FTZ NODES:STEPS [NODES:STEPS ...]\n", argv[0]);
        return 2;
    }
    if (std::atoi(argv[2])) {
        _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
        _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
    }
    std::ifstream in(argv[1], std::ios::binary | std::ios::ate);
    if (!in) {
        std::fprintf(stderr, "cannot read %s\n", argv[1]);
        return 2;
    }
    std::vector<float> raw(static_cast<size_t>(in.tellg()) / sizeof(float));
    in.seekg(0);
    in.read(reinterpret_cast<char*>(raw.data()), raw.size() * sizeof(float));
    std::vector<Eigen::Vector3f> points;
    for (size_t i = 0; i + 2 < raw.size(); i += 3) points.emplace_back(raw[i], raw[i + 1], raw[i + 2]);
    for (int arg = 3; arg < argc; ++arg) {
        std::string size(argv[arg]);
        int nodes = std::stoi(size.substr(0, size.find(':')));
        long steps = std::stol(size.substr(size.find(':') + 1));
        gng::GNGParams params;
        params.max_nodes = nodes;
        gng::GNG3f model(params, 1);
        model.init(points[0], points[1]);
        model.train(points, params.lambda * nodes + 200000);
        double start = thread_seconds();
        model.train(points, static_cast<int>(steps));
        double seconds = thread_seconds() - start;
        std::printf("nodes %d steps %ld: %.0f steps/s\n", model.num_nodes(), steps, steps / seconds);
        std::fflush(stdout);
    }
    return 0;
}
