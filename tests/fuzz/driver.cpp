// Runs a libFuzzer target without libFuzzer, so that every build exercises it (also under the
// sanitizers): the files named on the command line, or else the target's seeds followed by a
// fixed number of deterministic mutations of them (byte flips, insertions, deletions, splices).
// With clang, -DTAHVEL_FUZZ=ON builds the same targets against libFuzzer for real fuzzing.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);
std::vector<std::string> fuzz_seeds();  // defined by each target

namespace {

struct Rng {  // xorshift64*: the same mutations on every machine
  std::uint64_t state = 0x9E3779B97F4A7C15ull;
  std::uint64_t next() {
    state ^= state >> 12;
    state ^= state << 25;
    state ^= state >> 27;
    return state * 0x2545F4914F6CDD1Dull;
  }
  std::size_t below(std::size_t n) { return n ? next() % n : 0; }
};

std::string mutate(const std::string& input, const std::vector<std::string>& seeds, Rng& rng) {
  std::string out = input;
  int edits = 1 + static_cast<int>(rng.below(4));
  for (int e = 0; e < edits; ++e) {
    switch (rng.below(5)) {
      case 0:
        if (!out.empty()) out[rng.below(out.size())] = static_cast<char>(rng.next());
        break;
      case 1:
        out.insert(rng.below(out.size() + 1), 1, "<>\"\\:_#@^. \n%/?{}"[rng.below(18)]);
        break;
      case 2:
        if (!out.empty()) out.erase(rng.below(out.size()), 1 + rng.below(8));
        break;
      case 3: {
        const std::string& other = seeds[rng.below(seeds.size())];
        if (!other.empty()) out.insert(rng.below(out.size() + 1), other.substr(rng.below(other.size())));
        break;
      }
      default:
        out.insert(rng.below(out.size() + 1), 1, static_cast<char>(0x80 | rng.below(0x80)));
    }
  }
  return out;
}

void run(const std::string& input) {
  LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(input.data()), input.size());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1) {
    for (int i = 1; i < argc; ++i) {
      std::ifstream in(argv[i], std::ios::binary);
      run(std::string(std::istreambuf_iterator<char>(in), {}));
    }
    return 0;
  }
  const std::vector<std::string> seeds = fuzz_seeds();
  const char* env = std::getenv("TAHVEL_FUZZ_RUNS");
  const long runs = env ? std::atol(env) : 20000;
  Rng rng;
  for (const auto& seed : seeds) run(seed);
  for (long i = 0; i < runs; ++i) run(mutate(seeds[rng.below(seeds.size())], seeds, rng));
  std::printf("%ld mutated inputs survived\n", runs);
  return 0;
}
