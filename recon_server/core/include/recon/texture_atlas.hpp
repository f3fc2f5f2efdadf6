// The texture atlas of a finished model: the surface unwrapped into a picture (UV charts) and each texel painted
// from the colour frames that saw it best. Vertex colours (one per voxel-sized vertex) blur what the colour camera
// resolves; the atlas keeps the colour camera's own resolution.
//
//  1. Charts (textureCharts): the head is unwrapped around its vertical axis like a cylinder, with the cut at the
//     back of the head, so the face (forehead to chin, ear to ear) is one seamless piece; triangles that face up
//     or down along the axis (the crown, under the chin) go to planar charts of their own, projected along the
//     axis. Charts are packed on shelves into one image with a margin between them.
//  2. Baking (bakeTexture): each texel's surface point is projected into every view with the colour camera's
//     intrinsics and pose (colour need not be registered to depth); a view counts where it sees the point (a
//     z-buffer of the mesh in that view, so occluded points are not painted from it), weighted by how squarely it
//     faces the camera (cos^2 of the angle), how near it is (1/z^2: texels per pixel), how far it lies from a
//     depth edge of the view (silhouettes and jumps, where colour and depth disagree most and where the
//     projector's shadow falls) and how sharp the view is (the Laplacian's spread over
//     the image's own contrast, so that a dark view is not taken for a blurred one), and by how near the point
//     lands to one of the view's pixel centres: there the view holds the point's own colour, between centres only
//     an interpolation of its neighbours, which blurs. The views see the surface at different sub-pixel offsets,
//     so the blend of a texel's best eight views is a reconstruction from all their pixels, finer than any one
//     view resampled (and their JPEG noise averages out). Weights change smoothly from view to view: no seam.
//     Each view's exposure is evened out by a per-view, per-channel gain that matches it to what the other views
//     saw of the texels they share (three rounds; the median gain is 1, so the odd view is brought to the rest).
//  3. Texels no view saw take the vertex colours; every chart is padded by a few texels so that filtering and
//     mipmaps do not bleed the background into it.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/indexed_mesh.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

// One colour frame for baking: the image as the colour camera took it and where that camera was.
struct TextureView {
    cv::Mat colour_bgr;                     // CV_8UC3 at the colour camera's resolution
    Intrinsics colour;                      // the colour camera's intrinsics (its size must match colour_bgr)
    Pose T_colour_mesh = Pose::Identity();  // maps the mesh's frame (metres) into this colour camera
};

// The largest atlas side a server may be set to (TextureParams::max_atlas_px): what a client accepts from any server.
inline constexpr int kMaxAtlasPxLimit = 16384;  // pixels

struct TextureParams {
    // metres of surface per texel; 0 = the colour camera's own resolution: the median distance from the views to
    // the mesh divided by their focal length, over `texels_per_pixel`
    float texel_m = 0.0f;
    // texels per colour pixel when texel_m is 0 (ratio, in (0, 4]); 2: resampling a pixel into one texel blurs it
    // (facescan-bench texture: +3.1 dB over vertex colours at 1280x720 with 2, +2.8 dB with 1)
    float texels_per_pixel = 2.0f;
    int max_atlas_px = 8192;  // pixels; the atlas side at most (8192^2 RGB is 192 MiB, what a GPU still loads)
    // bytes the bake may hold at once (the atlas and about 150 bytes a texel of working state); above: an error
    // that names the size, before anything is allocated
    size_t max_memory_bytes = size_t{512} << 20;
    int padding_px = 4;          // texels each chart is grown by, and kept between charts
    float cap_cos = 0.8f;        // a triangle whose normal is within acos(cap_cos) of the head's axis is a cap
    float min_view_cos = 0.2f;   // a view at more than acos(min_view_cos) (78 deg) from the normal is not used
    float occlusion_m = 0.004f;  // metres; a point this far behind a view's z-buffer is hidden from that view
    float depth_edge_m = 0.01f;  // metres; a depth jump at least this large between neighbours is an edge
    float edge_band_px = 12.0f;  // pixels (of the colour image) from an edge over which a view's weight rises
    // the views' weights raised to this before blending (1: as they are; 4 lets the best view dominate, which kept
    // more of the JPEG noise: facescan-bench texture at 640x480, -0.2 dB with the pixel-centre weight below)
    float weight_power = 1.0f;
    // pixels; a view's weight for a texel falls off as a Gaussian of this spread with the distance from where the
    // texel lands in its image to the nearest pixel centre: a view that sampled the point itself counts more than
    // one that only interpolates between its pixels (which blurs). 0: off
    float pixel_centre_sigma_px = 0.25f;
    bool even_exposure = true;    // per-view gains matched to the blend (false: colours as captured)
    float min_mean_luma = 10.0f;  // 8-bit luma; a darker view is taken as missing colour (lens cap, no light)
    // resampling of the colour images: Keys' cubic convolution (sharper where the atlas is finer than the
    // pixels; facescan-bench texture at 640x480: +1.02 dB over vertex colours against +0.86 bilinear) or, false,
    // bilinear
    bool bicubic = true;

    Status validate() const;
};

// A mesh with texture coordinates: the finished mesh's vertices, split where charts meet (a vertex on a cut has
// one copy per side); positions, normals and vertex colours are kept, so the vertex colours stay available.
struct TexturedMesh {
    IndexedMesh mesh;
    std::vector<Eigen::Vector2f> uv;  // per vertex; glTF's convention: (0, 0) the image's top-left corner, v down
    cv::Mat atlas_bgr;                // CV_8UC3
    // The index in the input mesh each vertex copies (for code that keeps per-vertex data).
    std::vector<uint32_t> source_vertex;

    bool valid() const { return !mesh.triangles.empty() && uv.size() == mesh.vertexCount() && !atlas_bgr.empty(); }
};

struct TextureReport {
    int atlas_width_px = 0, atlas_height_px = 0;
    int charts = 0;
    float texel_mm = 0;         // millimetres of surface per texel
    size_t texels_surface = 0;  // texels inside a triangle
    size_t texels_unseen = 0;   // of those, painted from the vertex colours (no view saw them)
    int views_given = 0;
    int views_used = 0;                                    // views that painted at least one texel
    int views_dark = 0;                                    // views left out as too dark
    std::vector<Eigen::Vector3f> gains;                    // per view given, B G R (1 = unchanged)
    double ms_charts = 0, ms_visibility = 0, ms_bake = 0;  // milliseconds, wall clock
    std::vector<std::string> notes;

    std::string summary() const;
    std::string json() const;
};

// The UV charts of `mesh` (step 1) without colour: out.mesh/uv/source_vertex are set, out.atlas_bgr is allocated
// (black). `views` give the head's up and front (the first view's up, the mean view direction); without views the
// mesh is taken in a camera frame looking at the face (y down). InvalidArgument for bad params or a mesh without
// triangles; ResourceExhausted when the atlas would exceed max_atlas_px (the message names the size it needed).
StatusOr<TextureReport> textureCharts(const IndexedMesh& mesh, const std::vector<TextureView>& views,
                                      const TextureParams& params, TexturedMesh& out);

// Steps 1-3. FailedPrecondition-like errors come back as InvalidArgument with what to do: no views, a view whose
// image does not match its intrinsics, every view too dark. On error `out` is left empty and the caller keeps the
// vertex-coloured mesh.
StatusOr<TextureReport> bakeTexture(const IndexedMesh& mesh, const std::vector<TextureView>& views,
                                    const TextureParams& params, TexturedMesh& out);

}  // namespace facescan::recon
