// The finishing stage's triangle budget (finishing.hpp): quadric error decimation, Garland and Heckbert (1997),
// through OpenMesh's Decimater. Half-edge collapses move no kept vertex, so every vertex of the result is a
// measured one with its measured colour.
//
// The boundary (the scan's rim, holes left open) is held by Garland and Heckbert's constraint planes: for each
// boundary edge, the plane through it perpendicular to its triangle, added to its two vertices' quadrics with a
// high weight. OpenMesh's ModQuadricT has no such planes (and keeps its quadrics private), hence this module; the
// collapse order, the legality tests and the heap are OpenMesh's. Locking the boundary instead held the rim
// exactly but starved small budgets: a 30-frame scan's 2,100 rim vertices left a 2,000-triangle budget nothing
// but a fan across the face (6 mm from the full mesh).
#include <OpenMesh/Tools/Decimater/ModBaseT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>  // QuadricT, with the traits it needs
#include <string>

#include "recon/decimation_mesh.hpp"
#include "recon/finishing.hpp"

namespace facescan::recon {
namespace {

// A rim plane counts this many times a triangle of the same edge length: the rim moves far less than the surface
// for the same error, so it survives until the budget leaves no other choice.
constexpr double kRimWeight = 10.0;

template <class MeshT>
class ModRimQuadricT : public OpenMesh::Decimater::ModBaseT<MeshT> {
 public:
    DECIMATING_MODULE(ModRimQuadricT, MeshT, RimQuadric);

    explicit ModRimQuadricT(MeshT& mesh) : Base(mesh, false) { Base::mesh().add_property(quadrics_); }
    ~ModRimQuadricT() override { Base::mesh().remove_property(quadrics_); }

    void initialize() override {
        MeshT& m = Base::mesh();
        for (const auto vh : m.vertices()) m.property(quadrics_, vh).clear();
        for (const auto fh : m.faces()) {
            const auto h0 = m.halfedge_handle(fh);
            const auto h1 = m.next_halfedge_handle(h0);
            const OpenMesh::Vec3d p0 = OpenMesh::vector_cast<OpenMesh::Vec3d>(m.point(m.from_vertex_handle(h0)));
            const OpenMesh::Vec3d p1 = OpenMesh::vector_cast<OpenMesh::Vec3d>(m.point(m.to_vertex_handle(h0)));
            const OpenMesh::Vec3d p2 = OpenMesh::vector_cast<OpenMesh::Vec3d>(m.point(m.to_vertex_handle(h1)));
            OpenMesh::Vec3d n = (p1 - p0) % (p2 - p0);
            const double twice_area = n.norm();
            if (twice_area <= 0) continue;
            n /= twice_area;
            // The triangle's plane, weighted by its area (ModQuadricT's weighting).
            Q q(n[0], n[1], n[2], -(p0 | n));
            q *= 0.5 * twice_area;
            for (const auto vh : m.fv_range(fh)) m.property(quadrics_, vh) += q;
            // Its boundary edges' constraint planes.
            for (const auto heh : m.fh_range(fh)) {
                if (!m.is_boundary(m.opposite_halfedge_handle(heh))) continue;
                const auto va = m.from_vertex_handle(heh), vb = m.to_vertex_handle(heh);
                const OpenMesh::Vec3d a = OpenMesh::vector_cast<OpenMesh::Vec3d>(m.point(va));
                const OpenMesh::Vec3d b = OpenMesh::vector_cast<OpenMesh::Vec3d>(m.point(vb));
                OpenMesh::Vec3d side = (b - a) % n;
                const double length = side.norm();
                if (length <= 0) continue;
                side /= length;
                Q rim(side[0], side[1], side[2], -(a | side));
                rim *= kRimWeight * length * length;
                m.property(quadrics_, va) += rim;
                m.property(quadrics_, vb) += rim;
            }
        }
    }

    float collapse_priority(const CollapseInfo& ci) override {
        Q q = Base::mesh().property(quadrics_, ci.v0);
        q += Base::mesh().property(quadrics_, ci.v1);
        return static_cast<float>(q(ci.p1));
    }

    void postprocess_collapse(const CollapseInfo& ci) override {
        Base::mesh().property(quadrics_, ci.v1) += Base::mesh().property(quadrics_, ci.v0);
    }

 private:
    using Q = OpenMesh::Geometry::QuadricT<double>;
    OpenMesh::VPropHandleT<Q> quadrics_;
};

}  // namespace

void decimate(IndexedMesh& mesh, int max_triangles, FinishReport& report) {
    if (max_triangles <= 0 || mesh.triangleCount() <= static_cast<size_t>(max_triangles)) return;
    const bool colours = mesh.hasColours();
    DecimationMesh om(toOpenMesh(mesh));
    om.request_vertex_status();
    om.request_edge_status();
    om.request_face_status();
    om.prepare();
    LazyFlipDecimater<DecimationMesh> decimater(om);  // no collapse turns a face over
    ModRimQuadricT<DecimationMesh>::Handle quadric;
    decimater.add(quadric);
    if (!decimater.initialize()) {
        report.notes.push_back("the decimater could not start: the full mesh is delivered");
        return;
    }
    decimater.decimateToFaces(static_cast<size_t>(max_triangles));
    om.garbage_collection();
    IndexedMesh out = fromOpenMesh(static_cast<const Mesh&>(om));
    if (!colours) out.colours_rgb.clear();
    computeVertexNormals(out);
    if (out.triangleCount() > static_cast<size_t>(max_triangles)) {
        report.budget_reached = false;
        report.notes.push_back("the budget of " + std::to_string(max_triangles) + " triangles was not reached (" +
                               std::to_string(out.triangleCount()) +
                               " left): no further collapse keeps the surface from folding over");
    }
    mesh = std::move(out);
}

}  // namespace facescan::recon
