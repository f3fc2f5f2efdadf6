// The finishing stage's triangle budget (finishing.hpp): quadric error decimation, Garland and Heckbert (1997),
// through OpenMesh's Decimater. Half-edge collapses move no kept vertex, so every vertex of the result is a
// measured one with its measured colour; boundary vertices are locked, so the scan's rim and open holes stay.
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModNormalFlippingT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>
#include <string>

#include "recon/finishing.hpp"

namespace facescan::recon {

void decimate(IndexedMesh& mesh, int max_triangles, FinishReport& report) {
    if (max_triangles <= 0 || mesh.triangleCount() <= static_cast<size_t>(max_triangles)) return;
    const bool colours = mesh.hasColours();
    Mesh om = toOpenMesh(mesh);
    om.request_vertex_status();
    om.request_edge_status();
    om.request_face_status();
    size_t locked = 0;
    for (const auto vh : om.vertices()) {
        if (om.is_boundary(vh)) {
            om.status(vh).set_locked(true);
            ++locked;
        }
    }
    using Decimater = OpenMesh::Decimater::DecimaterT<Mesh>;
    Decimater decimater(om);
    OpenMesh::Decimater::ModQuadricT<Mesh>::Handle quadric;
    OpenMesh::Decimater::ModNormalFlippingT<Mesh>::Handle no_flips;  // a collapse must not turn a face over
    decimater.add(quadric);
    decimater.add(no_flips);
    decimater.module(quadric).unset_max_err();  // the budget decides, not an error bound
    if (!decimater.initialize()) {
        report.notes.push_back("the decimater could not start: the full mesh is delivered");
        return;
    }
    decimater.decimate_to_faces(0, static_cast<size_t>(max_triangles));
    om.garbage_collection();
    IndexedMesh out = fromOpenMesh(om);
    if (!colours) out.colours_rgb.clear();
    computeVertexNormals(out);
    if (out.triangleCount() > static_cast<size_t>(max_triangles)) {
        report.budget_reached = false;
        report.notes.push_back("the budget of " + std::to_string(max_triangles) + " triangles was not reached (" +
                               std::to_string(out.triangleCount()) + " left): " + std::to_string(locked) +
                               " boundary vertices are kept where they are; fill holes or crop to go lower");
    }
    mesh = std::move(out);
}

}  // namespace facescan::recon
