#pragma once
// Multi-brick models in the public API (docs/MODEL_FORMAT.md, "Multi-brick models"). load_model(path)
// opens a model directory like a .vnr file: the Model it returns carries the bricks (Model::bricks), and
// ModelQuery, evaluate_model(_file), Renderer and `vnr info` answer for the whole volume, blending the
// bricks. The planning, per-brick training, manifest and region decodes live in vnr/train/bricks.h;
// this header adds what a distributed front end (the MPI layer) needs on top of them.
#include <string>
#include <vector>
#include "vnr/model.h"
#include "vnr/renderer.h"
#include "vnr/train/bricks.h"

namespace vnr {

// The bricked part of a model opened by load_model (null for a single-network model).
inline const BrickedModel* bricked(const Model& m) { return m.bricks.get(); }

// Sort-last rendering: the part of every ray inside brick `index`'s owned box, as premultiplied RGBA
// (no background), from the renderer's current settings. Samples lie on the same global t grid as the
// whole-volume frame, so compositing the bricks' images front to back in visibility order
// (brick_visibility_order) gives the single-process frame up to float rounding.
Image render_brick_segment(Renderer& renderer, int index);
// Brick indices front to back as seen from the camera (for a convex brick grid: sorted by the
// distance of the camera from each brick's box).
std::vector<int> brick_visibility_order(const BrickPlan& plan, const Camera& camera, Vec3f box);

}  // namespace vnr
