// A facescan mesh as glTF 2.0 binary through TinyGLTF: the buffers are laid out here (glTF's accessors need
// 4-byte aligned elements, so colours are RGBA), TinyGLTF writes the JSON chunk and the GLB container.
#include "client/gltf_mesh.hpp"

#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

#include "recon/mesh_writer.hpp"

namespace facescan::client {
namespace {

// Appends `count` elements of `bytes_each` bytes to the buffer and adds a view and an accessor for them.
int addAccessor(tinygltf::Model& model, const void* data, size_t count, size_t bytes_each, int component_type, int type,
                bool normalized, int target) {
    std::vector<unsigned char>& buffer = model.buffers[0].data;
    const size_t offset = buffer.size();  // every block's size is a multiple of 4: offsets stay aligned
    buffer.resize(offset + count * bytes_each);
    std::memcpy(buffer.data() + offset, data, count * bytes_each);

    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = offset;
    view.byteLength = count * bytes_each;
    view.target = target;
    model.bufferViews.push_back(view);

    tinygltf::Accessor accessor;
    accessor.bufferView = static_cast<int>(model.bufferViews.size() - 1);
    accessor.componentType = component_type;
    accessor.count = count;
    accessor.type = type;
    accessor.normalized = normalized;
    model.accessors.push_back(accessor);
    return static_cast<int>(model.accessors.size() - 1);
}

// The GLB of `mesh`; with `uv` and `png` (a textured mesh) also TEXCOORD_0 and the PNG as the material's base colour
// texture.
StatusOr<std::string> glb(const recon::IndexedMesh& mesh, const std::vector<Eigen::Vector2f>* uv,
                          const std::string* png) {
    std::vector<float> positions, normals;
    std::vector<uint8_t> colours;
    // glTF viewers light with NORMAL: always send it, from the triangles when the mesh has none.
    const std::vector<Eigen::Vector3f> vertex_normals = mesh.hasNormals() ? mesh.normals : recon::vertexNormals(mesh);
    // glTF multiplies COLOR_0 into the base colour texture: a textured GLB leaves the vertex colours out (they
    // stay in the PLY and OBJ).
    const bool has_colours = mesh.hasColours() && uv == nullptr;
    const bool has_normals = true;
    std::array<double, 3> lo{}, hi{};
    lo.fill(std::numeric_limits<double>::max());
    hi.fill(std::numeric_limits<double>::lowest());
    const uint32_t n = static_cast<uint32_t>(mesh.vertexCount());
    for (uint32_t i = 0; i < n; ++i) {
        const Eigen::Vector3f& p = mesh.positions_m[i];
        if (!p.allFinite()) return invalidArgument("glTF export: vertex " + std::to_string(i) + " is not finite");
        // 180 degrees about x: camera frame (y down, z forward) to glTF's (y up, viewer on +z).
        const float q[3] = {p[0], -p[1], -p[2]};
        for (int k = 0; k < 3; ++k) {
            positions.push_back(q[k]);
            lo[k] = std::min(lo[k], double(q[k]));
            hi[k] = std::max(hi[k], double(q[k]));
        }
        Eigen::Vector3f nv = vertex_normals[i];
        if (!nv.allFinite() || nv.squaredNorm() < 1e-12f) nv = Eigen::Vector3f(0, 0, -1);
        nv.normalize();
        normals.insert(normals.end(), {nv[0], -nv[1], -nv[2]});
        if (has_colours) {
            const recon::Rgb8& c = mesh.colours_rgb[i];
            colours.insert(colours.end(), {c[0], c[1], c[2], 255});
        }
    }
    std::vector<uint32_t> indices;
    indices.reserve(mesh.triangleCount() * 3);
    for (const recon::Triangle& t : mesh.triangles) {
        if (t[0] >= n || t[1] >= n || t[2] >= n)
            return invalidArgument("glTF export: a triangle indexes past the vertices");
        indices.insert(indices.end(), t.begin(), t.end());
    }
    if (indices.empty()) return invalidArgument("glTF export: the mesh has no triangles");

    tinygltf::Model model;
    model.asset.version = "2.0";
    model.asset.generator = "facescan";
    model.buffers.resize(1);
    tinygltf::Primitive primitive;
    primitive.mode = TINYGLTF_MODE_TRIANGLES;
    const int position = addAccessor(model, positions.data(), n, 12, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3,
                                     false, TINYGLTF_TARGET_ARRAY_BUFFER);
    model.accessors[position].minValues.assign(lo.begin(), lo.end());  // required for POSITION by the spec
    model.accessors[position].maxValues.assign(hi.begin(), hi.end());
    primitive.attributes["POSITION"] = position;
    if (has_normals) {
        primitive.attributes["NORMAL"] = addAccessor(model, normals.data(), n, 12, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                                     TINYGLTF_TYPE_VEC3, false, TINYGLTF_TARGET_ARRAY_BUFFER);
    }
    if (has_colours) {
        primitive.attributes["COLOR_0"] =
            addAccessor(model, colours.data(), n, 4, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_TYPE_VEC4, true,
                        TINYGLTF_TARGET_ARRAY_BUFFER);
    }
    if (uv != nullptr) {  // glTF's texture coordinates are ours: (0, 0) the image's top-left corner
        std::vector<float> coords;
        coords.reserve(uv->size() * 2);
        for (const Eigen::Vector2f& t : *uv) coords.insert(coords.end(), {t.x(), t.y()});
        primitive.attributes["TEXCOORD_0"] = addAccessor(model, coords.data(), n, 8, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                                         TINYGLTF_TYPE_VEC2, false, TINYGLTF_TARGET_ARRAY_BUFFER);
    }
    primitive.indices = addAccessor(model, indices.data(), indices.size(), 4, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                                    TINYGLTF_TYPE_SCALAR, false, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);

    // glTF's default material is fully metallic, which renders black without an environment: a matte one instead.
    // Double-sided: a scan is an open surface, seen from behind when it is turned around.
    tinygltf::Material material;
    material.name = "facescan";
    material.pbrMetallicRoughness.metallicFactor = 0.0;
    material.pbrMetallicRoughness.roughnessFactor = 0.9;
    material.doubleSided = true;
    if (png != nullptr) {
        // The PNG inside the binary chunk (a buffer view, 4-byte aligned like every block), one linear sampler.
        std::vector<unsigned char>& buffer = model.buffers[0].data;
        const size_t offset = buffer.size();
        buffer.insert(buffer.end(), png->begin(), png->end());
        buffer.resize((buffer.size() + 3) / 4 * 4, 0);
        tinygltf::BufferView view;
        view.buffer = 0;
        view.byteOffset = offset;
        view.byteLength = png->size();
        model.bufferViews.push_back(view);
        tinygltf::Image image;
        image.name = "atlas";
        image.mimeType = "image/png";
        image.bufferView = static_cast<int>(model.bufferViews.size() - 1);
        model.images.push_back(image);
        tinygltf::Sampler sampler;
        sampler.magFilter = TINYGLTF_TEXTURE_FILTER_LINEAR;
        sampler.minFilter = TINYGLTF_TEXTURE_FILTER_LINEAR_MIPMAP_LINEAR;
        sampler.wrapS = TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
        sampler.wrapT = TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
        model.samplers.push_back(sampler);
        tinygltf::Texture texture;
        texture.sampler = 0;
        texture.source = 0;
        model.textures.push_back(texture);
        material.pbrMetallicRoughness.baseColorTexture.index = 0;
        material.pbrMetallicRoughness.baseColorTexture.texCoord = 0;
    }
    model.materials.push_back(material);
    primitive.material = 0;

    tinygltf::Mesh gltf_mesh;
    gltf_mesh.name = "face";
    gltf_mesh.primitives.push_back(primitive);
    model.meshes.push_back(gltf_mesh);
    tinygltf::Node node;
    node.mesh = 0;
    node.name = "face";
    model.nodes.push_back(node);
    tinygltf::Scene scene;
    scene.nodes.push_back(0);
    model.scenes.push_back(scene);
    model.defaultScene = 0;

    std::ostringstream out(std::ios::binary);
    tinygltf::TinyGLTF writer;
    if (!writer.WriteGltfSceneToStream(&model, out, /*prettyPrint=*/false, /*writeBinary=*/true)) {
        return internalError("TinyGLTF could not write the GLB");
    }
    return out.str();
}

}  // namespace

StatusOr<std::string> meshToGlb(const recon::IndexedMesh& mesh) { return glb(mesh, nullptr, nullptr); }

StatusOr<std::string> meshToGlb(const recon::Mesh& mesh) { return meshToGlb(recon::fromOpenMesh(mesh)); }

StatusOr<std::string> meshToGlb(const recon::TexturedMesh& mesh) {
    if (mesh.uv.size() != mesh.mesh.vertexCount() || mesh.atlas_bgr.empty()) {
        return invalidArgument("glTF export: the mesh has no texture (texture coordinates and an atlas are needed)");
    }
    ASSIGN_OR_RETURN(const std::string png, recon::atlasPngBytes(mesh));
    return glb(mesh.mesh, &mesh.uv, &png);
}

}  // namespace facescan::client
