// Finishing's decimation (mesh_decimate.cpp): the mesh it works on (OpenMesh's, with its collapse test done here)
// and the decimater (OpenMesh's heap decimater, with its test against turned-over faces done lazily).
#pragma once

#include <OpenMesh/Tools/Decimater/BaseDecimaterT.hh>
#include <OpenMesh/Tools/Utils/HeapT.hh>
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <memory>
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

// OpenMesh's DecimaterT (a heap of vertices, each keyed by its best legal collapse, re-keyed around every collapse)
// with its test against turning a face over (ModNormalFlippingT at 90 degrees: every face that stays around v0
// keeps its normal within 90 degrees) made lazily: a vertex is keyed by its best collapse by the quadric alone, and
// only the collapse at the top of the heap is tested; one that would turn a face over sends its vertex back, keyed
// by its best collapse that passes. A key without the test is never above the key with it, and the faces around a
// vertex do not change between its keying and its turn (a collapse re-keys its whole one-ring), so what is taken
// is what the eager decimater takes, except that a vertex keyed again after a refusal sees the quadrics around it
// as they are then (the eager key may be older): the same collapses in number, the same distances on the tests
// (recon_finishing_test), not always the very same triangles. The test runs about once a collapse instead of once
// per candidate: a third of the decimation's CPU before (perf on facescan-bench finish).
template <class MeshT>
class LazyFlipDecimater : public OpenMesh::Decimater::BaseDecimaterT<MeshT> {
 public:
    using Base = OpenMesh::Decimater::BaseDecimaterT<MeshT>;
    using CollapseInfo = typename Base::CollapseInfo;
    using VertexHandle = typename MeshT::VertexHandle;
    using HalfedgeHandle = typename MeshT::HalfedgeHandle;

    explicit LazyFlipDecimater(MeshT& mesh) : Base(mesh), mesh_(mesh) {
        mesh_.add_property(target_);
        mesh_.add_property(priority_);
        mesh_.add_property(position_);
        mesh_.request_face_normals();
        mesh_.update_face_normals();
    }
    ~LazyFlipDecimater() override {
        mesh_.remove_property(target_);
        mesh_.remove_property(priority_);
        mesh_.remove_property(position_);
        mesh_.release_face_normals();
    }

    // Collapses until at most `max_faces` are left or no legal collapse is; returns the collapses.
    size_t decimateToFaces(size_t max_faces) {
        if (!this->is_initialized() || max_faces >= mesh_.n_faces()) return 0;
        size_t faces = mesh_.n_faces(), collapses = 0;
        heap_ = std::make_unique<Heap>(HeapInterface(mesh_, priority_, position_));
        heap_->reserve(mesh_.n_vertices());
        for (const auto vh : mesh_.vertices()) {
            heap_->reset_heap_position(vh);
            if (!mesh_.status(vh).deleted()) heapVertex(vh, false);
        }
        std::vector<VertexHandle> support;
        while (!heap_->empty() && max_faces < faces) {
            const VertexHandle vp = heap_->front();
            const HalfedgeHandle v0v1 = mesh_.property(target_, vp);
            heap_->pop_front();
            CollapseInfo ci(mesh_, v0v1);
            if (!this->is_collapse_legal(ci)) continue;
            if (unchecked(vp) && turnsAFaceOver(ci)) {
                heapVertex(vp, true);
                continue;
            }
            support.clear();
            for (const auto vh : mesh_.vv_range(ci.v0)) support.push_back(vh);
            ++collapses;
            faces -= mesh_.is_boundary(ci.v0v1) || mesh_.is_boundary(ci.v1v0) ? 1 : 2;
            this->preprocess_collapse(ci);
            mesh_.collapse(v0v1);
            for (const auto fh : mesh_.vf_range(ci.v1)) {
                if (!mesh_.status(fh).deleted()) mesh_.set_normal(fh, mesh_.calc_face_normal(fh));
            }
            this->postprocess_collapse(ci);
            for (const VertexHandle vh : support) heapVertex(vh, false);
        }
        heap_.reset();
        return collapses;
    }

 private:
    class HeapInterface {
     public:
        HeapInterface(MeshT& mesh, OpenMesh::VPropHandleT<float> prio, OpenMesh::VPropHandleT<int> pos)
            : mesh_(&mesh), prio_(prio), pos_(pos) {}
        bool less(VertexHandle a, VertexHandle b) { return mesh_->property(prio_, a) < mesh_->property(prio_, b); }
        bool greater(VertexHandle a, VertexHandle b) { return mesh_->property(prio_, a) > mesh_->property(prio_, b); }
        int get_heap_position(VertexHandle v) { return mesh_->property(pos_, v); }
        void set_heap_position(VertexHandle v, int p) { mesh_->property(pos_, v) = p; }

     private:
        MeshT* mesh_;
        OpenMesh::VPropHandleT<float> prio_;
        OpenMesh::VPropHandleT<int> pos_;
    };
    using Heap = OpenMesh::Utils::HeapT<VertexHandle, HeapInterface>;

    bool unchecked(VertexHandle v) const {
        return unchecked_.size() > static_cast<size_t>(v.idx()) && unchecked_[v.idx()];
    }

    // ModNormalFlippingT's test at 90 degrees, in its terms: v0 moved to p1, the stored normal of every face around
    // v0 but the two that go against its new normal.
    bool turnsAFaceOver(const CollapseInfo& ci) {
        static const double kMinCos = std::cos(M_PI / 2);
        mesh_.set_point(ci.v0, ci.p1);
        bool over = false;
        for (const auto fh : mesh_.vf_range(ci.v0)) {
            if (fh == ci.fl || fh == ci.fr) continue;
            if (OpenMesh::dot(mesh_.normal(fh), mesh_.calc_face_normal(fh)) < kMinCos) {
                over = true;
                break;
            }
        }
        mesh_.set_point(ci.v0, ci.p0);
        return over;
    }

    // Keys v by its best legal collapse (the quadric's priority; with `check`, only those that turn no face over).
    // The priorities first, then the legality from the best priority down, until one is legal: both are pure
    // tests, so this is the collapse a scan in the one-ring's order would keep (the lowest priority that is legal,
    // the first in that order among equals), but the legality (the link condition over two one-rings, and the
    // decimater's search for an edge vl-vr), the dearer test, runs about once a vertex instead of once for each
    // collapse that beats the best so far.
    void heapVertex(VertexHandle v, bool check) {
        float best = FLT_MAX;
        HalfedgeHandle target;
        ranked_.clear();
        for (const auto heh : mesh_.voh_range(v)) {
            const float prio = this->collapse_priority(CollapseInfo(mesh_, heh));
            if (prio >= 0.0f && prio < FLT_MAX) ranked_.emplace_back(prio, heh);
        }
        // Insertion sort, stable (a one-ring holds about six; std::stable_sort would allocate a buffer each call).
        for (size_t i = 1; i < ranked_.size(); ++i) {
            for (size_t j = i; j > 0 && ranked_[j].first < ranked_[j - 1].first; --j) {
                std::swap(ranked_[j], ranked_[j - 1]);
            }
        }
        for (const auto& [prio, heh] : ranked_) {
            CollapseInfo ci(mesh_, heh);
            if (!this->is_collapse_legal(ci)) continue;
            if (check && turnsAFaceOver(ci)) continue;
            best = prio;
            target = heh;
            break;
        }
        if (unchecked_.size() < mesh_.n_vertices()) unchecked_.resize(mesh_.n_vertices(), 0);
        unchecked_[v.idx()] = !check;
        mesh_.property(target_, v) = target;
        if (target.is_valid()) {
            mesh_.property(priority_, v) = best;
            if (heap_->is_stored(v)) {
                heap_->update(v);
            } else {
                heap_->insert(v);
            }
        } else {
            if (heap_->is_stored(v)) heap_->remove(v);
            mesh_.property(priority_, v) = -1;
        }
    }

    MeshT& mesh_;
    OpenMesh::VPropHandleT<HalfedgeHandle> target_;
    OpenMesh::VPropHandleT<float> priority_;
    OpenMesh::VPropHandleT<int> position_;
    std::vector<uint8_t> unchecked_;                        // per vertex: keyed without the test
    std::vector<std::pair<float, HalfedgeHandle>> ranked_;  // heapVertex's candidates (kept for their capacity)
    std::unique_ptr<Heap> heap_;
};

}  // namespace facescan::recon
