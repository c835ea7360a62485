// Many COLMAP scenes ranked by the appendix D.4 scene score (`macro bench pairs --root`): every
// immediate sub-folder of a root that holds a COLMAP model is loaded and constructed one at a
// time (enhance/datasets/pair_construction.h), ranked by S, filtered by --min-score then --top,
// and the selected splits written; the ranking is written as JSON, Markdown and CSV.
// docs/benchmark.md "Pair construction" describes the choices.
//
// What it does not: run scenes in parallel (each construction is parallel inside), or keep the
// splits of an earlier run that are no longer selected (those files are removed, so the folder
// holds exactly the selection that `bench run --root` takes).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "enhance/datasets/pair_construction.h"

namespace macro::enhance {

// `macro bench pairs --root`: every immediate sub-folder holding a COLMAP model, ranked by S.
struct RootParams {
  PairParams pair;      // pair.progress is ignored: one progress line over the scenes
  std::string root;     // folder of scene folders
  std::string out_dir;  // empty: splits in ROOT/<scene>/, ranking files in ROOT
  std::string split_name = "split.json";
  int top = 0;                      // keep the best `top` scenes (0: all)
  std::optional<double> min_score;  // keep scenes with S >= min_score
  bool copy_gt = false;
  bool overwrite = false;  // replace a split file that `bench pairs` did not write
  bool progress = true;    // scenes done / elapsed / ETA on stderr
};

enum class SceneStatus { kSelected, kBelowMinScore, kNotInTop, kFailed };
const char* scene_status_name(
    SceneStatus s);  // "selected", "below_min_score", "not_in_top", "failed"

struct RankedScene {
  std::string name, folder;
  std::string split_path;  // where its split is (selected) or would be written
  SceneStatus status = SceneStatus::kFailed;
  std::string reason;   // why it failed or was not selected ("" when selected)
  bool scored = false;  // the construction ran, so `score` holds S (0 without candidates)
  SceneScore score;
  int64_t cameras = 0, points = 0, close = 0, far = 0, training = 0, eval_pairs = 0;
  bool removed_stale_split = false;  // a split of an earlier `bench pairs` run was deleted
  double seconds = 0;                // load + construction + write
  int rank = 0;                      // 1-based row of the table
};

struct SceneRanking {
  std::vector<RankedScene> scenes;   // table order: S descending (no score last), ties by name
  std::vector<std::string> ignored;  // sub-folders without a COLMAP model, by name
  int constructed = 0, failed = 0, selected = 0;
};

// The immediate sub-folders of `root` that hold a COLMAP model (gs::find_colmap_model_folder),
// sorted by name; the others (hidden ones, starting with '.', are skipped silently) go to
// `ignored` when it is not null. An error if root is not a folder.
Result<std::vector<std::string>> list_scene_folders(const std::string& root,
                                                    std::vector<std::string>* ignored);

// Processes every scene (one at a time, each construction parallel inside), ranks, applies
// min_score then top over the constructed scenes, writes the selected splits and removes the
// earlier splits of this command (files with a "pair_construction" record) for the others. A
// failing scene is recorded with its reason and never stops the others. Errors: bad root, no
// scene in it, invalid params.
Result<SceneRanking> rank_scenes(const RootParams& params);

// The ranking as JSON (params, counts, one object per scene), Markdown (a table, then the reasons)
// and CSV (one row per scene, full precision), and all three written atomically to
// OUT/ranking.{json,md,csv} (OUT = out_dir or root).
std::string ranking_json(const SceneRanking& ranking, const RootParams& params);
std::string ranking_markdown(const SceneRanking& ranking, const RootParams& params);
std::string ranking_csv(const SceneRanking& ranking);
Status write_ranking(const SceneRanking& ranking, const RootParams& params);
std::string ranking_dir(const RootParams& params);

}  // namespace macro::enhance
