// macro bench run|merge|report: the evaluation harness (enhance/bench/bench_harness.h) and its
// tables and charts (enhance/bench/bench_report.h). docs/benchmark.md describes the protocol and
// the files.
#include <cstdio>
#include <sstream>

#include "apps/args.h"
#include "apps/bench_commands.h"
#include "attention/runtime/file_io.h"
#include "enhance/bench/bench_harness.h"
#include "enhance/bench/bench_report.h"

namespace macro::cli {

std::vector<BenchCommand>& bench_registry() {
  static std::vector<BenchCommand> registry;
  return registry;
}
bool register_bench_command(BenchCommand command) {
  bench_registry().push_back(command);
  return true;
}
const std::vector<BenchCommand>& bench_commands() {
  return bench_registry();
}

namespace {

constexpr const char* kUsage =
    "usage: macro bench run --root DIR --results FILE.jsonl [--methods 3dgs,...]\n"
    "                       [--K 1,3] [--P 4] [--mask on,off] [--precision bf16,f32]\n"
    "                       [--crop full,tight,composite] [--upsampler lanczos,pft-sr]\n"
    "                       [--rounds 15] [--round-steps 2000]\n"
    "                       [--shard i/N] [--limit N] [--weights DIFIX_DIR] [--ctx "
    "CTX.safetensors]\n"
    "                       [--lpips-backbone F] [--lpips-heads F]\n"
    "                       [--dinov2 F] [--dreamsim F] [--quiet] [--threads N]\n"
    "       macro bench merge FILE.jsonl... --out FILE.jsonl\n"
    "       macro bench report --results FILE.jsonl --out REPORT_DIR\n"
    "                       [--scene-failure released|pair]\n"
    "  methods: 3dgs, mip-splatting (DIR/scene_mip.ply), transfer, transfer-whole (weight-free,\n"
    "           docs/transfer.md), difix, macro,\n"
    "           macro-unmasked (the Difix network methods need --weights),\n"
    "           difix3d, difix3d+, pr-difix3d, pr-difix3d+ (progressive fine-tuning of the\n"
    "           3DGS, docs/baselines.md: --rounds fixes --round-steps apart; released 15 x\n"
    "           2000; Difix with --weights, else the weight-free transfer, named per record).\n"
    "  run     scores every (close-up pair, method, option set) of the scene folders under DIR\n"
    "          against closeup_gt/<frame>, appending one JSON line per record; a rerun resumes.\n"
    "          Option lists form a grid; each method records only the options it uses.\n"
    "  merge   joins shard results (deduplicated, work-list order), written atomically.\n"
    "  report  table.md, table.csv and PNG + SVG + PDF charts (mean over scenes of scene means).\n"
    "          --scene-failure released (default, paper-comparable): a scene with an empty\n"
    "          k-means bin in any pair drops out of that method's average, as in the release;\n"
    "          pair: those pairs count (the plane is dropped). table.md names the rule used.\n";

std::vector<std::string> split_list(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

int run_run(Args& args) {
  enhance::BenchRunOptions o;
  o.root = args.required("--root");
  o.results = args.required("--results");
  o.methods = split_list(args.value_or("--methods", "3dgs"));
  std::map<std::string, std::vector<std::string>> grid;
  for (const char* key : {"K", "P", "mask", "precision", "crop", "upsampler"})
    if (auto v = args.value(std::string("--") + key)) grid[key] = split_list(*v);
  if (auto v = args.value("--rounds")) grid["rounds"] = split_list(*v);
  if (auto v = args.value("--round-steps")) grid["round_steps"] = split_list(*v);
  o.option_sets = enhance::expand_option_grid(grid);
  const std::string shard = args.value_or("--shard", "0/1");
  o.limit = args.int_or("--limit", 0, 0, 1 << 30);
  o.metrics.lpips_backbone = args.value_or("--lpips-backbone", "");
  o.metrics.lpips_heads = args.value_or("--lpips-heads", "");
  o.metrics.dinov2_weights = args.value_or("--dinov2", "");
  o.metrics.dreamsim_weights = args.value_or("--dreamsim", "");
  enhance::BenchMethodSettings settings;
  settings.difix_weights = args.value_or("--weights", "");
  settings.ctx_path = args.value_or("--ctx", "");
  if (Status s = args.finish(); !s) return fail("bench run", s);
  auto sh = enhance::parse_shard(shard);
  if (!sh) return fail("bench run", sh.status());
  o.shard = *sh;
  if (Status s = prepare_output(o.results, "--results", {".jsonl"}); !s)
    return fail("bench run", s);
  const enhance::MethodRegistry registry = enhance::default_method_registry(settings);
  auto summary = enhance::run_benchmark(o, registry);
  if (!summary) return fail("bench run", summary.status());
  std::printf(
      "bench run: %s in shard %d/%d, %zu already done, %zu run (%zu ok, %zu "
      "skipped) -> %s\n",
      count_noun(summary->work_items, "item").c_str(), o.shard.index, o.shard.count,
      summary->already_done, summary->ran, summary->ok, summary->skipped, o.results.c_str());
  return 0;
}

int run_merge(Args& args) {
  const std::string out = args.required("--out");
  const std::vector<std::string> inputs = args.positionals();
  if (Status s = args.finish(); !s) return fail("bench merge", s);
  if (inputs.empty()) return fail("bench merge", Status::error("no input results file given"));
  if (Status s = check_output_name(out, "--out", {".jsonl"}); !s) return fail("bench merge", s);
  std::vector<std::vector<enhance::BenchRecord>> lists;
  for (const std::string& path : inputs) {
    if (!file_exists(path)) return fail("bench merge", Status::error(path + ": not found"));
    auto records = enhance::read_records(path);
    if (!records) return fail("bench merge", records.status());
    lists.push_back(std::move(*records));
  }
  const auto merged = enhance::merge_records(lists);
  if (Status s = prepare_output(out, "--out", {".jsonl"}); !s) return fail("bench merge", s);
  if (Status s = enhance::write_records_atomic(out, merged); !s) return fail("bench merge", s);
  std::printf("bench merge: %s from %s -> %s\n", count_noun(merged.size(), "record").c_str(),
              count_noun(inputs.size(), "file").c_str(), out.c_str());
  return 0;
}

int run_report(Args& args) {
  const std::string results = args.required("--results");
  const std::string out = args.required("--out");
  const std::string failure = args.value_or("--scene-failure", "released");
  if (Status s = args.finish(); !s) return fail("bench report", s);
  auto rule = enhance::parse_scene_failure_rule(failure);
  if (!rule) return fail("bench report", rule.status());
  if (!file_exists(results)) return fail("bench report", Status::error(results + ": not found"));
  if (Status s = prepare_output_dir(out, "--out"); !s) return fail("bench report", s);
  auto records = enhance::read_records(results);
  if (!records) return fail("bench report", records.status());
  std::vector<std::string> written;
  if (Status s = enhance::write_report(*records, out, &written, *rule); !s)
    return fail("bench report", s);
  const auto configs = enhance::aggregate_records(*records, *rule);
  const std::string table = enhance::table_markdown(configs);
  std::fwrite(table.data(), 1, table.size(), stdout);
  std::printf("bench report: %s -> %s\n", count_noun(written.size(), "file").c_str(), out.c_str());
  return 0;
}

void print_usage(std::FILE* to) {
  std::fprintf(to, "%s", kUsage);
  for (const BenchCommand& c : bench_commands()) std::fprintf(to, "%s", c.usage);
}

int run_bench(std::vector<std::string> argv) {
  if (argv.empty() || argv[0] == "--help" || argv[0] == "-h" || argv[0] == "help") {
    print_usage(argv.empty() ? stderr : stdout);
    return argv.empty() ? 1 : 0;
  }
  const std::string sub = argv[0];
  Args args(std::vector<std::string>(argv.begin() + 1, argv.end()));
  if (args.flag("--help")) {
    print_usage(stdout);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("bench " + sub, s);
  if (sub == "run") return run_run(args);
  if (sub == "merge") return run_merge(args);
  if (sub == "report") return run_report(args);
  std::string known = "run, merge, report";
  for (const BenchCommand& c : bench_commands()) {
    if (sub == c.name) return c.run(args);
    known += std::string(", ") + c.name;
  }
  print_usage(stderr);
  return fail("bench", Status::error("unknown subcommand '" + sub + "' (" + known + ")"));
}

const bool registered = register_command(
    {"bench", "evaluation harness: run methods on close-up pairs, merge, report", run_bench});

}  // namespace
}  // namespace macro::cli
