// Plan stability: how MACRO's plan of one close-up moves when the depth it is planned from is
// wrong. Plan A is built from the reconstruction's depth (the 3DGS render, as MACRO runs), plan B
// from the true depth (PlanOptions::closeup_depth); the measure compares the two.
//
// Legend: close-up W x H, latent grid h x w = H/8 x W/8 (MacroPlan::latent_planes, one token per
// cell), P_A / P_B planes (0 = farthest), crop (p, r) = plane p seen in reference r.
//
// Plane matching m: A plane -> B plane.
//   P_A == P_B: m(p) = p. Planes are numbered far to near in both plans, so the index is the
//               depth rank and equal indices are the same slab of the scene.
//   P_A != P_B: m(p) = the B plane whose inverse-depth centroid (the k-means centre) is nearest
//               to A plane p's, ties to the farther (lower index). Several A planes may map to
//               one B plane; a B plane no A plane maps to has no partner (its crops are unpaired).
// Definitions:
//   tokens moved    latent cells t with m(A[t]) != B[t]; fraction = moved / (h w). A cell whose
//                   64 pixels have no depth votes plane 0 in either plan (latent_plane_map).
//   pixels moved    close-up pixels with m(A) != B at render resolution, "no surface" (-1) kept
//                   as a class of its own (a pixel with depth in one plan only is moved).
//   plane depth     per A plane: |d_A / d_B(m) - 1|, d = the plane's lower-median depth.
//   crop pairs      A crop (p, r) pairs with B crop (m(p), r') where r' is the first B reference
//                   index holding the same candidate camera as A's r (the references may differ:
//                   crops are paired by camera, not by greedy rank). Crops without a partner
//                   (rejected in the other plan, another camera, an unmatched plane) are counted.
//   scale error     |scale_A / scale_B - 1| per pair (Crop::scale = W / crop width).
//   centre error    |(u_A, v_A) - (u_B, v_B)|_2 per pair, reference pixels (Crop::centre_*).
//   mean / max      over the pairs; 0 when there is none.
//   references      the same when both greedy lists hold the same candidates in the same order.
//
// What the crop maths predicts for a depth off by a factor (d_A = (1 + e) d_B for every pixel,
// --scale axis): the planes' disparities all scale by 1 / (1 + e), and 1-D k-means with quantile
// initial centres is scale-equivariant, so the labels (and tokens) do not move and every plane's
// median scales by (1 + e). The scale is s_ref = (d_ref / d_in) (fx_cu / fx_ref) with d_ref the
// reference depth of the close-up centre ray's point at d_in: affine in d_in, d_ref = a d_in + b
// (a = the z row of R_ref R_cu^T applied to the ray, b = d_ref at d_in = 0: the close-up camera
// centre's depth in the reference). So
//   scale_A / scale_B = (a + b / ((1 + e) d)) / (a + b / d),
//   scale error       = (|e| / (1 + e)) |b| / d_ref,B,
// 0 for a reference at the close-up's centre (b = 0), and -> |1 / (1 + e) - 1| for a reference
// far behind it (b >> a d: the crop scale goes as 1 / d_in). Tested on an analytic scene
// (tests/test_plan_stability.cpp), with the tokens moved by a moved rectangle counted by hand.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "enhance/macro/plan.h"

namespace macro::enhance {

struct PlaneStability {
  int plane_a = 0, plane_b = 0;  // plane_b = m(plane_a)
  double depth_a = 0, depth_b = 0;
  double depth_error = 0;  // |depth_a / depth_b - 1|
};

struct CropStability {
  int plane_a = 0, plane_b = 0;
  int ref_a = 0, ref_b = 0;  // reference indices (greedy order) in each plan
  int candidate = 0;         // the candidate camera both crops are cut from
  std::string reference;     // its name
  double scale_a = 0, scale_b = 0, scale_error = 0;
  double centre_a_u = 0, centre_a_v = 0, centre_b_u = 0, centre_b_v = 0, centre_error = 0;
};

struct PlanStability {
  std::string closeup;
  int width = 0, height = 0;       // close-up W x H
  int latent_h = 0, latent_w = 0;  // h x w
  int planes_a = 0, planes_b = 0;
  bool planes_by_index = true;         // P_A == P_B (else matched by inverse-depth centroid)
  std::vector<int> plane_match;        // [P_A] m(p)
  std::vector<PlaneStability> planes;  // [P_A]
  int64_t tokens = 0, tokens_moved = 0;
  double tokens_moved_fraction = 0;
  int64_t pixels = 0, pixels_moved = 0;
  double pixels_moved_fraction = 0;
  std::vector<CropStability> crops;  // pairs, in A's view order
  int crops_a = 0, crops_b = 0;      // crops in each plan
  int crops_unpaired_a = 0, crops_unpaired_b = 0;
  double scale_error_mean = 0, scale_error_max = 0;
  double centre_error_mean = 0, centre_error_max = 0;
  double depth_error_mean = 0, depth_error_max = 0;  // over the A planes
  bool same_references = true;
  std::vector<int> candidates_a, candidates_b;          // [K] greedy order
  std::vector<std::string> references_a, references_b;  // [K] their names
};

// The measure between two plans of the same close-up (a: the reconstruction's, b: the true
// depth's). Error when the close-ups differ in size.
Result<PlanStability> compare_plans(const MacroPlan& a, const MacroPlan& b);

// Plans the close-up twice with `options`: A as given (the render's depth unless
// options.closeup_depth is set), B from true_depth (its camera must have the close-up's size,
// its depth W x H values in the MACRO convention), and compares them.
Result<PlanStability> plan_stability(const SceneInputs& inputs, const PlanOptions& options,
                                     const DepthView& true_depth);

// The close-up's MACRO depth rendered from another splat (the ground-truth cloud of a synthetic
// scene, e.g. SynthClose gt.ply), with options.render: the true depth for plan_stability.
Result<DepthView> render_closeup_depth(const gs::GaussianCloud& cloud, const gs::Camera& closeup,
                                       const PlanOptions& options);

// JSON: closeup {name, size [W,H], latent [w,h]}, planes {a, b, by_index, match [P_A],
// depth [{a, b, depth_a, depth_b, error}], depth_error {mean, max}}, tokens {total, moved,
// fraction}, pixels {total, moved, fraction}, crops {a, b, unpaired_a, unpaired_b, scale_error
// {mean, max}, centre_error_px {mean, max}, pairs [{plane_a, plane_b, ref_a, ref_b, candidate,
// reference, scale [a, b], scale_error, centre_a [u,v], centre_b [u,v], centre_error_px}]},
// references {same, a [names], b [names], candidates_a, candidates_b}.
std::string plan_stability_to_json(const PlanStability& s);
Status write_plan_stability_json(const PlanStability& s, const std::string& path);

}  // namespace macro::enhance
