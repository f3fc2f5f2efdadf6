// The payload codecs of the wire (docs/design.md section 3): lossless depth, JPEG colour, Draco mesh.
// Every decoder of network bytes checks sizes and counts before it allocates and returns a Status; each one has
// a libFuzzer target in tests/fuzz (run with deploy/fuzz.sh).
#pragma once

#include "wire/colour_codec.hpp"
#include "wire/depth_codec.hpp"
#include "wire/mesh_codec.hpp"
