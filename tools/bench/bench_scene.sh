# Sourced by the issue-5 benches: the in-core scene of their figures (spheres, two point
# lights, a diffuse default material, a grey-blue background).
#   bench_scene FILE STORE WIDTH HEIGHT INTEGRATOR SPP SEED   (the scene's output: FILE's name.exr)
bench_scene() {
  local file=$1
  cat > "$file" <<JSON
{ "store": "$2",
  "camera": { "position": [0, 5.5, 10.5], "look_at": [0, 0.4, 0], "up": [0, 1, 0],
              "fov_y_deg": 40, "width": $3, "height": $4 },
  "lights": [ { "type": "point", "position": [4, 9, 6], "intensity": [160, 150, 140] },
              { "type": "point", "position": [-6, 5, -2], "intensity": [20, 25, 40] } ],
  "materials": { "default": { "type": "diffuse", "albedo": [0.75, 0.72, 0.68] } },
  "background": [0.35, 0.4, 0.5],
  "integrator": { "type": "$5", "max_depth": 4, "spp": $6, "seed": $7 },
  "output": "$(basename "$file" .json).exr" }
JSON
}
