// Scene ranking (scene_ranking.h): each scene loaded and constructed, ranked by S, filtered,
// the selected splits written and the earlier ones of the others removed; the ranking files.
#include "enhance/datasets/scene_ranking.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numeric>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "attention/runtime/text.h"
#include "gs/cameras/colmap_points.h"

namespace macro::enhance {
namespace {

// A split file this command wrote: a JSON object with a "pair_construction" record.
bool is_generated_split(const std::string& path) {
  auto text = read_text_file(path, 1ull << 28);
  if (!text) return false;
  const nlohmann::json j = nlohmann::json::parse(*text, nullptr, /*allow_exceptions=*/false);
  return j.is_object() && j.contains("pair_construction");
}

std::string join_path(const std::string& a, const std::string& b) {
  return (std::filesystem::path(a) / b).string();
}

std::string score_text(const RankedScene& r, const char* format) {
  if (!r.scored) return "-";
  char buf[48];
  std::snprintf(buf, sizeof buf, format, r.score.score);
  return buf;
}

}  // namespace

const char* scene_status_name(SceneStatus s) {
  switch (s) {
    case SceneStatus::kSelected:
      return "selected";
    case SceneStatus::kBelowMinScore:
      return "below_min_score";
    case SceneStatus::kNotInTop:
      return "not_in_top";
    case SceneStatus::kFailed:
      return "failed";
  }
  return "?";
}

std::string ranking_dir(const RootParams& rp) {
  return rp.out_dir.empty() ? rp.root : rp.out_dir;
}

Result<std::vector<std::string>> list_scene_folders(const std::string& root,
                                                    std::vector<std::string>* ignored) {
  namespace fs = std::filesystem;
  if (!is_directory(root)) return Status::error(root + ": folder not found");
  std::error_code ec;
  fs::directory_iterator it(root, ec), end;
  if (ec) return Status::error(root + ": cannot list the folder: " + ec.message());
  std::vector<std::string> scenes, others;
  for (; it != end; it.increment(ec)) {
    if (ec) return Status::error(root + ": cannot list the folder: " + ec.message());
    std::error_code dir_ec;
    if (!it->is_directory(dir_ec)) continue;
    const std::string name = it->path().filename().string();
    if (name.empty() || name[0] == '.') continue;
    (gs::find_colmap_model_folder(it->path().string()).is_ok() ? scenes : others).push_back(name);
  }
  std::sort(scenes.begin(), scenes.end());
  std::sort(others.begin(), others.end());
  if (ignored) *ignored = std::move(others);
  return scenes;
}

Result<SceneRanking> rank_scenes(const RootParams& rp) {
  namespace fs = std::filesystem;
  MACRO_TRY(check_pair_params(rp.pair));
  if (rp.top < 0)
    return Status::error("scene ranking: top: expected >= 0 (0 keeps all), found " +
                         std::to_string(rp.top));
  if (rp.min_score && !(*rp.min_score >= 0.0 && std::isfinite(*rp.min_score)))
    return Status::error("scene ranking: minimum score: expected a finite number >= 0, found " +
                         format_number(*rp.min_score, 6));
  if (rp.split_name.empty() || rp.split_name == "." || rp.split_name == ".." ||
      rp.split_name.find('/') != std::string::npos)
    return Status::error("scene ranking: split file name: expected a plain file name, found '" +
                         rp.split_name + "'");
  SceneRanking out;
  MACRO_ASSIGN_OR_RETURN(std::vector<std::string> names, list_scene_folders(rp.root, &out.ignored));
  if (names.empty())
    return Status::error(rp.root + ": no sub-folder holds a COLMAP model (cameras.{bin,txt} or " +
                         "images.{bin,txt} in <scene>, <scene>/sparse/0, <scene>/sparse or " +
                         "<scene>/colmap/sparse/0); " + std::to_string(out.ignored.size()) +
                         " other sub-folders");
  PairParams p = rp.pair;
  p.progress = false;  // one line over the scenes instead
  const std::string base = ranking_dir(rp);

  // 1. Load and construct every scene, one at a time (the construction is parallel inside).
  std::vector<RankedScene> rows(names.size());
  std::vector<std::optional<SceneSplit>> built(names.size());
  {
    std::optional<Progress> progress;
    if (rp.progress) progress.emplace("pairs: scenes", names.size());
    for (size_t k = 0; k < names.size(); ++k) {
      const auto t0 = std::chrono::steady_clock::now();
      RankedScene& r = rows[k];
      r.name = names[k];
      r.folder = join_path(rp.root, names[k]);
      r.split_path = join_path(join_path(base, names[k]), rp.split_name);
      auto scene = load_and_construct(r.folder, r.name, p);
      if (!scene) {
        r.reason = scene.status().message();
      } else {
        const PairConstruction& pc = scene->pc;
        r.scored = true;
        r.score = pc.score;
        r.cameras = int64_t(scene->cameras.cameras.size());
        r.points = scene->num_points;
        r.close = int64_t(pc.close_set.size());
        r.far = int64_t(pc.far_set.size());
        r.training = int64_t(pc.training.size());
        r.eval_pairs = int64_t(pc.eval_pairs.size());
        if (Status found = check_pairs_found(pc, p); !found) {
          r.reason = found.with_context(scene->model).message();
        } else {
          r.status = SceneStatus::kSelected;  // for now; the filters come next
          built[k] = std::move(*scene);
        }
      }
      r.seconds = ms_since(t0) / 1000.0;
      if (progress) progress->advance();
    }
    if (progress) progress->finish();
  }

  // 2. Rank: S descending (scenes without a score last), ties by name; then the filters over the
  // scenes that have a split, in rank order: --min-score first, then --top.
  std::vector<size_t> order(rows.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    const auto key = [](const RankedScene& r) {  // NaN cannot occur (d > 0), but never sorts
      return r.scored && !std::isnan(r.score.score) ? r.score.score : -INFINITY;
    };
    const double sa = key(rows[a]), sb = key(rows[b]);
    if (sa != sb) return sa > sb;
    return rows[a].name < rows[b].name;
  });
  int kept = 0;
  for (size_t i : order) {
    RankedScene& r = rows[i];
    if (r.status != SceneStatus::kSelected) continue;
    if (rp.min_score && r.score.score < *rp.min_score) {
      r.status = SceneStatus::kBelowMinScore;
      r.reason = "S = " + format_number(r.score.score, 6) + " < --min-score " +
                 format_number(*rp.min_score, 6);
    } else if (rp.top > 0 && kept >= rp.top) {
      r.status = SceneStatus::kNotInTop;
      r.reason = "not among the --top " + std::to_string(rp.top) + " scenes";
    } else if (!rp.overwrite && file_exists(r.split_path) && !is_generated_split(r.split_path)) {
      r.status = SceneStatus::kFailed;  // checked here so that it does not take a --top place
      r.reason = r.split_path +
                 ": exists and was not written by `bench pairs` (no \"pair_construction\" "
                 "record); not replaced (--overwrite replaces it, --out-dir writes elsewhere)";
    } else {
      ++kept;
    }
  }

  // 3. Write the selected splits; remove this command's earlier splits of the others, so the
  // folder holds exactly the selection (`bench run --root` takes every split it finds).
  {
    std::optional<Progress> progress;
    if (rp.progress && kept > 0) progress.emplace("pairs: writing splits", size_t(kept));
    for (size_t i : order) {
      RankedScene& r = rows[i];
      const auto t0 = std::chrono::steady_clock::now();
      const bool exists = file_exists(r.split_path);
      if (r.status != SceneStatus::kSelected) {
        if (exists && is_generated_split(r.split_path)) {
          std::error_code ec;
          r.removed_stale_split = fs::remove(r.split_path, ec) && !ec;
        }
        continue;
      }
      Status written = Status::ok();
      std::error_code ec;
      fs::create_directories(fs::path(r.split_path).parent_path(), ec);
      if (ec)
        written = Status::error(fs::path(r.split_path).parent_path().string() +
                                ": cannot create folder: " + ec.message());
      else
        written = write_scene_split(*built[i], p, r.split_path, rp.copy_gt);
      if (!written) {
        r.status = SceneStatus::kFailed;
        r.reason = written.message();
        if (exists && is_generated_split(r.split_path)) {
          std::error_code rm;
          r.removed_stale_split = fs::remove(r.split_path, rm) && !rm;
        }
      }
      r.seconds += ms_since(t0) / 1000.0;
      built[i].reset();
      if (progress) progress->advance();
    }
    if (progress) progress->finish();
  }

  for (size_t i : order) out.scenes.push_back(std::move(rows[i]));
  for (size_t k = 0; k < out.scenes.size(); ++k) {
    RankedScene& r = out.scenes[k];
    r.rank = int(k) + 1;
    out.constructed += r.status != SceneStatus::kFailed;
    out.failed += r.status == SceneStatus::kFailed;
    out.selected += r.status == SceneStatus::kSelected;
  }
  return out;
}

std::string ranking_json(const SceneRanking& ranking, const RootParams& rp) {
  using Json = nlohmann::ordered_json;
  const PairParams& p = rp.pair;
  Json scenes = Json::array();
  for (const RankedScene& r : ranking.scenes) {
    Json row = {{"rank", r.rank},
                {"scene", r.name},
                {"status", scene_status_name(r.status)},
                {"reason", r.reason},
                {"score", r.scored ? Json(r.score.score) : Json(nullptr)}};
    if (r.scored) {
      row["score_factors"] = {{"depth_cv", r.score.depth_cv},
                              {"mean_span", r.score.mean_span},
                              {"near_ratio", r.score.near_ratio},
                              {"closeness", r.score.closeness}};
      row["candidate_pairs"] = r.score.candidates;
      row["eval_pairs"] = r.eval_pairs;
      row["close"] = r.close;
      row["far"] = r.far;
      row["training_views"] = r.training;
      row["cameras"] = r.cameras;
      row["points"] = r.points;
    }
    row["folder"] = r.folder;
    row["split"] = r.status == SceneStatus::kSelected ? Json(r.split_path) : Json(nullptr);
    row["removed_stale_split"] = r.removed_stale_split;
    row["seconds"] = r.seconds;
    scenes.push_back(row);
  }
  Json doc = {
      {"method", "appendix D.4 scene score (docs/benchmark.md, Pair construction)"},
      {"root", rp.root},
      {"out_dir", ranking_dir(rp)},
      {"split_name", rp.split_name},
      {"params",
       {{"training_views", p.training_views},
        {"min_depth_ratio", p.min_depth_ratio},
        {"min_iou", p.min_iou},
        {"angle_deg", {p.min_angle_deg, p.max_angle_deg}},
        {"fps_start", p.seed ? "seed " + std::to_string(*p.seed) : "farthest from centroid"},
        {"top", rp.top},
        {"min_score", rp.min_score ? Json(*rp.min_score) : Json(nullptr)}}},
      {"counts",
       {{"scenes", ranking.scenes.size()},
        {"constructed", ranking.constructed},
        {"failed", ranking.failed},
        {"selected", ranking.selected},
        {"ignored_folders", ranking.ignored.size()}}},
      {"scenes", scenes},
      {"ignored_folders", ranking.ignored}};
  return doc.dump(2) + "\n";
}

std::string ranking_markdown(const SceneRanking& ranking, const RootParams& rp) {
  std::string md = "# Scene ranking (appendix D.4)\n\n";
  md += "Root `" + rp.root + "`: " + count_noun(ranking.scenes.size(), "scene") + ", " +
        std::to_string(ranking.constructed) + " with pairs, " + std::to_string(ranking.failed) +
        " failed, " + std::to_string(ranking.selected) + " selected";
  if (rp.min_score) md += " (--min-score " + format_number(*rp.min_score, 6) + ")";
  if (rp.top > 0) md += " (--top " + std::to_string(rp.top) + ")";
  md += ".\n\n| rank | scene | S | eval pairs | candidates | close | far | training | status |\n";
  md += "|---:|---|---:|---:|---:|---:|---:|---:|---|\n";
  for (const RankedScene& r : ranking.scenes) {
    const auto count = [&](int64_t v) { return r.scored ? std::to_string(v) : std::string("-"); };
    md += "| " + std::to_string(r.rank) + " | " + r.name + " | " + score_text(r, "%.6g") + " | " +
          count(r.eval_pairs) + " | " + count(r.score.candidates) + " | " + count(r.close) + " | " +
          count(r.far) + " | " + count(r.training) + " | " + scene_status_name(r.status) + " |\n";
  }
  bool any_reason = false;
  for (const RankedScene& r : ranking.scenes) {
    if (r.reason.empty() && !r.removed_stale_split) continue;
    if (!any_reason) md += "\n";
    any_reason = true;
    md += "- " + r.name + " (" + scene_status_name(r.status) + "): " + r.reason;
    if (r.removed_stale_split)
      md += std::string(r.reason.empty() ? "" : "; ") + "removed the split of an earlier run";
    md += "\n";
  }
  if (!ranking.ignored.empty()) {
    md += "\nNot COLMAP scenes (ignored):";
    for (const std::string& n : ranking.ignored) md += " " + n;
    md += "\n";
  }
  return md;
}

std::string ranking_csv(const SceneRanking& ranking) {
  const auto quote = [](const std::string& s) {
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
  };
  std::string csv =
      "rank,scene,status,score,eval_pairs,candidate_pairs,close,far,training_views,cameras,"
      "points,split,reason\n";
  for (const RankedScene& r : ranking.scenes) {
    const auto count = [&](int64_t v) { return r.scored ? std::to_string(v) : std::string(); };
    csv += std::to_string(r.rank) + "," + quote(r.name) + "," + scene_status_name(r.status) + "," +
           (r.scored ? score_text(r, "%.17g") : std::string()) + "," + count(r.eval_pairs) + "," +
           count(r.score.candidates) + "," + count(r.close) + "," + count(r.far) + "," +
           count(r.training) + "," + count(r.cameras) + "," + count(r.points) + "," +
           (r.status == SceneStatus::kSelected ? quote(r.split_path) : std::string()) + "," +
           quote(r.reason) + "\n";
  }
  return csv;
}

Status write_ranking(const SceneRanking& ranking, const RootParams& rp) {
  const std::string dir = ranking_dir(rp);
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Status::error(dir + ": cannot create folder: " + ec.message());
  MACRO_TRY(write_file_atomic(join_path(dir, "ranking.md"), ranking_markdown(ranking, rp)));
  MACRO_TRY(write_file_atomic(join_path(dir, "ranking.csv"), ranking_csv(ranking)));
  return write_file_atomic(join_path(dir, "ranking.json"), ranking_json(ranking, rp));
}

}  // namespace macro::enhance
