// The mesh that finishing's decimation (mesh_decimate.cpp) works on: OpenMesh's, with its collapse test done here.
#pragma once

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include "recon/mesh.hpp"

namespace facescan::recon {

// OpenMesh's mesh with the collapse test (TriConnectivity::is_collapse_ok, which the decimater calls through its mesh
// type, so this one hides it) done here, with the same tests in the same order of meaning:
// Debian's libOpenMeshCore 9.0 is built with its assertions and spent a third of the decimation in that one
// function (perf on facescan-bench finish). The one-ring intersection (the link condition) marks v1's neighbours
// with a stamp instead of the status' tag bits, so nothing is cleared first.
class DecimationMesh : public Mesh {
 public:
    explicit DecimationMesh(Mesh&& mesh) : Mesh(std::move(mesh)) {}

    // After request_*_status: the status arrays, which a decimation never resizes (it adds no element).
    void prepare() {
        vertex_status_ = property(vertex_status_pph()).data_vector().data();
        edge_status_ = property(edge_status_pph()).data_vector().data();
        stamp_.assign(n_vertices(), 0);
        epoch_ = 0;
    }

    bool is_collapse_ok(HalfedgeHandle v0v1) {
        if (edge_status_[edge_handle(v0v1).idx()].deleted()) return false;
        const HalfedgeHandle v1v0 = opposite_halfedge_handle(v0v1);
        const VertexHandle v0 = to_vertex_handle(v1v0), v1 = to_vertex_handle(v0v1);
        if (vertex_status_[v0.idx()].deleted() || vertex_status_[v1.idx()].deleted()) return false;
        // The edges v1-vl and vl-v0 must not both be boundary edges, nor v0-vr and vr-v1.
        VertexHandle vl, vr;
        if (!is_boundary(v0v1)) {
            const HalfedgeHandle h1 = next_halfedge_handle(v0v1), h2 = next_halfedge_handle(h1);
            vl = to_vertex_handle(h1);
            if (is_boundary(opposite_halfedge_handle(h1)) && is_boundary(opposite_halfedge_handle(h2))) return false;
        }
        if (!is_boundary(v1v0)) {
            const HalfedgeHandle h1 = next_halfedge_handle(v1v0), h2 = next_halfedge_handle(h1);
            vr = to_vertex_handle(h1);
            if (is_boundary(opposite_halfedge_handle(h1)) && is_boundary(opposite_halfedge_handle(h2))) return false;
        }
        if (vl == vr) return false;  // both invalid, or the same vertex on both sides
        // The one-rings of v0 and v1 share vl and vr only.
        if (++epoch_ == 0) std::fill(stamp_.begin(), stamp_.end(), 0), epoch_ = 1;
        forNeighbours(v1, [this](VertexHandle w) {
            stamp_[w.idx()] = epoch_;
            return true;
        });
        const bool link_ok =
            forNeighbours(v0, [&](VertexHandle w) { return stamp_[w.idx()] != epoch_ || w == vl || w == vr; });
        if (!link_ok) return false;
        // An edge between two boundary vertices must be a boundary edge.
        return !(is_boundary(v0) && is_boundary(v1) && !is_boundary(v0v1) && !is_boundary(v1v0));
    }

 private:
    // Calls f on each neighbour of v (its outgoing halfedges in turn) while f returns true; false if one did not.
    template <class F>
    bool forNeighbours(VertexHandle v, F&& f) {
        const HalfedgeHandle start = halfedge_handle(v);
        if (!start.is_valid()) return true;
        HalfedgeHandle h = start;
        do {
            if (!f(to_vertex_handle(h))) return false;
            h = next_halfedge_handle(opposite_halfedge_handle(h));
        } while (h != start);
        return true;
    }

    const OpenMesh::Attributes::StatusInfo* vertex_status_ = nullptr;
    const OpenMesh::Attributes::StatusInfo* edge_status_ = nullptr;
    std::vector<uint32_t> stamp_;
    uint32_t epoch_ = 0;
};

}  // namespace facescan::recon
