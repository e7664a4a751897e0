#pragma once
// Multi-brick models in the public API (docs/MODEL_FORMAT.md, "Multi-brick models"). load_model(path)
// opens a model directory like a .vnr file: the Model it returns carries the bricks (Model::bricks), and
// ModelQuery, evaluate_model(_file), Renderer and `vnr info` answer for the whole volume, blending the
// bricks. The planning, per-brick training, manifest and region decodes live in vnr/train/bricks.h;
// this header adds what a distributed front end (the MPI layer) needs on top of them.
#include <string>
#include "vnr/image.h"
#include <vector>
#include "vnr/model.h"
#include "vnr/renderer.h"
#include "vnr/train/bricks.h"
#include "vnr/train/evaluate.h"

namespace vnr {

// The bricked part of a model opened by load_model (null for a single-network model).
inline const BrickedModel* bricked(const Model& m) { return m.bricks.get(); }

// Distributed decode and evaluation: a rank opens its share (open_brick_share: contiguous_bricks(plan,
// rank, n) and their neighbours loaded), decodes
// brick_output_region of each, and evaluate_region(model, file, that region) gives its share of the
// evaluation (errors, and with SSIM the windows starting in it); the ranks' EvalSums add up to the
// single-process evaluation. The rank needs its bricks and those within 7 voxels loaded.

// Sort-last rendering (ray marching without shadows): brick `index`'s part of every ray of the renderer's
// current settings (frame 0), as premultiplied RGBA without background, and per pixel the ray
// parameter t of the brick's first sample (+inf where it has none). Samples lie on the same t grid as
// the whole-volume frame (the march and its macro-cells are the whole model's; a sample belongs to the
// brick owning its position), so composite_brick_segments of every brick's segment gives the
// single-process frame up to float rounding. Needs the bricks within ghost + 1 voxels of the brick
// loaded (gradients and the blend reach into them): bricks_touching(plan, owned box grown by ghost + 1).
// The march must see the same macro-cells on every rank: the merged online ranges need every brick
// loaded (model_of_bricks gives none when some are missing), so a rank holding only some bricks sets
// MacroCellMode::Off (or Grid from the volume) on its Renderer, as the reference frame must.
struct BrickSegment {
  int index = 0;
  Image rgba;                 // premultiplied, no background
  std::vector<float> t_first; // width * height
};
BrickSegment render_brick_segment(Renderer& renderer, int index);
// Front-to-back "over" of the segments per pixel, ordered by t_first, then the background.
Image composite_brick_segments(const std::vector<const BrickSegment*>& segments, Vec3f background);

}  // namespace vnr
