// SfM-like points for a SynthClose scene: what COLMAP would triangulate from the training photos,
// made from the ground truth instead (`macro bench synth --recon train` writes them to
// sparse/0/points3D.txt, so the trainer's SfM initialisation and `macro bench pairs` work on
// SynthClose as on a real capture).
//
// A GT Gaussian becomes a point when at least min_views training cameras see its centre: inside
// the image, in front, and not occluded (its depth within occlusion_tolerance x z of the GT's
// rendered depth at that pixel, where the GT is opaque: alpha > 0.5). Candidates are taken in a
// seeded random order until `points` are accepted (or every Gaussian was tried), each point's
// noise from a stream of its own (so a visibility test that flips with render rounding on another
// ISA path changes that point alone). Each point is
// then moved by Gaussian noise of noise_px pixels at its nearest seeing camera (sigma = noise_px
// z / fx per axis), its colour is the GT colour (SH band 0) plus uniform noise of +-color_noise,
// its error noise_px, and its track the seeing cameras (COLMAP image ids of `cameras`; 2D point
// indices count the observations per image, which images.txt does not list).
//
// Not modelled: SfM's preference for textured corners, its outliers and its missing surfaces.
#pragma once

#include <cstdint>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/colmap_points.h"
#include "gs/gaussians.h"

namespace macro::enhance {

struct SynthSfmOptions {
  size_t points = 20000;
  int min_views = 2;
  double noise_px = 0.5;
  double color_noise = 4.0 / 255.0;
  double occlusion_tolerance = 0.01;
  uint64_t seed = 1;
};

// cameras: the training cameras, each with its COLMAP image id (colmap_image_id > 0).
Result<gs::ColmapPoints> synth_sfm_points(const gs::GaussianCloud& gt,
                                          const std::vector<gs::Camera>& cameras,
                                          const SynthSfmOptions& options,
                                          ThreadPool& pool = ThreadPool::global());

}  // namespace macro::enhance
