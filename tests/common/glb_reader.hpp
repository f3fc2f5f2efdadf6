// A GLB (binary glTF 2.0) read back with TinyGLTF, the library the client writes it with: for the viewer's and the
// client's tests of the mesh downloads.
#pragma once

#include <tiny_gltf.h>

#include <string>

namespace facescan::testing {

// Parses `bytes` as a GLB into `model`; false with TinyGLTF's message in `error` when it is not one.
inline bool readGlb(const std::string& bytes, tinygltf::Model& model, std::string& error) {
    tinygltf::TinyGLTF reader;
    std::string warning;
    return reader.LoadBinaryFromMemory(&model, &error, &warning, reinterpret_cast<const unsigned char*>(bytes.data()),
                                       static_cast<unsigned>(bytes.size()));
}

}  // namespace facescan::testing
