#pragma once
// The range of positions float ray tracing is sound in. The watertight triangle test multiplies
// two coordinates (relative to the ray's origin): beyond ~1.8e19 the product overflows float,
// and below ~1e-19 it underflows, so a model, camera or light outside these limits would render
// wrong. raystack-prep refuses such models and the scene file such positions, each saying which
// way to scale.

namespace raystack {

// No coordinate (model vertex, camera, light) beyond +-kMaxCoordinate.
inline constexpr float kMaxCoordinate = 1e18f;
// No model smaller than this across.
inline constexpr float kMinModelExtent = 1e-15f;

}  // namespace raystack
