#pragma once
/// \file tiled_lattice.hpp
/// Values on the points of a lattice (a SampleLattice's dims: the half lattice of the level sets
/// and volume fractions) stored in tiles of 8^Dim points that exist only where something was
/// written, every other point reading a background value. For quantities that differ from their
/// background only in a band (around the liquid's particles, a moving body's surface): memory and
/// clearing in proportion to the band instead of the box (issue 20; at the paper's 256x128x256
/// grid one lattice-sized vector of doubles is 541 MB).
///
/// Each point holds `Stride` values of type T side by side (for example the Dim + 2 sums of a
/// particle splat: weight, radius, position). Tiles are made serially (touch_box, at) or from
/// flags marked on several threads (mark_box, make_tiles); once made,
/// find() / point() of distinct points may run on several threads at once (no tile is made
/// there). Tiles are ordered by tile index, points in a tile as the lattice orders them
/// (lattice_index: axis 0 fastest), so for_each_point visits the points in a fixed order.

#include <algorithm>
#include <cstddef>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

/// A process-wide store of released tile memory, one per element type and tile length (`Values`
/// elements per tile): blocks handed back by TiledLattice::reset and ~TiledLattice, taken by the
/// next tiles made. Holds at most kPoolBytes (blocks beyond it are freed). Thread-safe.
template <class T, std::size_t Values>
class TilePool {
 public:
  static constexpr std::size_t kPoolBytes = std::size_t(32) << 20;
  static constexpr std::size_t kMaxBlocks = std::max<std::size_t>(1, kPoolBytes / (Values * sizeof(T)));

  static TilePool& instance() {
    static TilePool pool;
    return pool;
  }
  /// Up to `count` blocks (their contents undefined), fewer when the pool holds fewer.
  void take(std::size_t count, std::vector<std::unique_ptr<T[]>>& out) {
    std::lock_guard<std::mutex> lock(mutex_);
    while (count-- > 0 && !blocks_.empty()) {
      out.push_back(std::move(blocks_.back()));
      blocks_.pop_back();
    }
  }
  /// Hands back the non-null blocks of `tiles` (each left null); those over the limit are freed.
  void give(std::vector<std::unique_ptr<T[]>>& tiles) {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto& t : tiles)
      if (t) {
        if (blocks_.size() < kMaxBlocks) blocks_.push_back(std::move(t));
        t.reset();
      }
  }

 private:
  std::mutex mutex_;
  std::vector<std::unique_ptr<T[]>> blocks_;
};

template <int Dim, class T, int Stride = 1>
class TiledLattice {
 public:
  static constexpr int kTile = 8;  ///< points per tile along each axis
  static constexpr int kTilePoints = Dim == 2 ? kTile * kTile : kTile * kTile * kTile;
  using Pool = TilePool<T, static_cast<std::size_t>(kTilePoints) * Stride>;

  TiledLattice() = default;
  TiledLattice(const VecI<Dim>& dims, T background) { reset(dims, background); }
  ~TiledLattice() { Pool::instance().give(tiles_); }
  TiledLattice(TiledLattice&&) = default;
  TiledLattice& operator=(TiledLattice&& other) {
    if (this != &other) {
      Pool::instance().give(tiles_);
      dims_ = other.dims_;
      tile_dims_ = other.tile_dims_;
      background_ = other.background_;
      tiles_ = std::move(other.tiles_);
      num_tiles_ = other.num_tiles_;
      other.tiles_.clear();
      other.num_tiles_ = 0;
    }
    return *this;
  }

  /// Empties the lattice: dims points per axis, every value `background`, no tile. The tile
  /// table (one pointer per tile) is kept when the dims do not change; the tiles' memory goes
  /// to the pool.
  void reset(const VecI<Dim>& dims, T background) {
    if ((dims.array() < 1).any())
      throw std::invalid_argument("TiledLattice: every axis needs at least one point");
    background_ = background;
    Pool::instance().give(tiles_);
    if (dims != dims_ || tiles_.empty()) {
      dims_ = dims;
      for (int a = 0; a < Dim; ++a) tile_dims_[a] = (dims[a] + kTile - 1) / kTile;
      tiles_.clear();
      tiles_.resize(static_cast<std::size_t>(tile_dims_.prod()));
    }
    num_tiles_ = 0;
  }

  const VecI<Dim>& dims() const { return dims_; }
  T background() const { return background_; }
  /// Tiles made so far, and the bytes their values take.
  int num_tiles() const { return num_tiles_; }
  std::size_t value_bytes() const {
    return static_cast<std::size_t>(num_tiles_) * kTilePoints * Stride * sizeof(T);
  }

  /// Makes every tile that holds a point of the box [lo, hi] (point coordinates, clamped to the
  /// lattice; an empty box makes none), its values the background. Serial.
  void touch_box(VecI<Dim> lo, VecI<Dim> hi) {
    for_each_tile_in_box(lo, hi, [&](int tile) { make_tile(tile); });
  }

  /// Tile flags for making tiles on several threads: mark_box sets the flag of every tile
  /// holding a point of the box [lo, hi] (clamped; flags: one per tile slot, made by
  /// tile_flags()), and may run on several threads at once; make_tiles then makes the flagged
  /// tiles, filling them in parallel. The same tiles as touch_box of every box.
  std::vector<unsigned char> tile_flags() const {
    return std::vector<unsigned char>(tiles_.size(), 0);
  }
  void mark_box(VecI<Dim> lo, VecI<Dim> hi, std::vector<unsigned char>& flags) const {
    for_each_tile_in_box(lo, hi, [&](int tile) {
      unsigned char& flag = flags[tile];
      // the same value from any thread (an integer store, no float atomics)
#pragma omp atomic write
      flag = 1;
    });
  }
  void make_tiles(const std::vector<unsigned char>& flags, int threads) {
    std::vector<T*> fresh = claim_tiles(flags);
    const int count = static_cast<int>(fresh.size());
#pragma omp parallel for schedule(static) num_threads(threads)
    for (int i = 0; i < count; ++i) fill_tile(fresh[i]);
  }
  /// make_tiles in two halves, for filling the tiles of several lattices in one parallel region:
  /// claim_tiles gives every flagged tile not yet made its memory (serial; from the pool first)
  /// and returns them, their values not yet set; fill_tile sets one to the background (distinct
  /// tiles on several threads at once). Every returned tile must be filled before it is read.
  std::vector<T*> claim_tiles(const std::vector<unsigned char>& flags) {
    const int slots = num_tile_slots();
    std::size_t wanted = 0;
    for (int tile = 0; tile < slots; ++tile) wanted += flags[tile] && !tiles_[tile];
    std::vector<std::unique_ptr<T[]>> blocks;
    blocks.reserve(wanted);
    Pool::instance().take(wanted, blocks);
    std::vector<T*> fresh;
    fresh.reserve(wanted);
    std::size_t next = 0;
    for (int tile = 0; tile < slots; ++tile) {
      if (!flags[tile] || tiles_[tile]) continue;
      if (next < blocks.size())
        tiles_[tile] = std::move(blocks[next++]);
      else
        tiles_[tile].reset(new T[static_cast<std::size_t>(kTilePoints) * Stride]);
      fresh.push_back(tiles_[tile].get());
    }
    num_tiles_ += static_cast<int>(fresh.size());
    return fresh;
  }
  void fill_tile(T* data) const {
    std::fill(data, data + static_cast<std::size_t>(kTilePoints) * Stride, background_);
  }

  /// The Stride values of point c, making its tile if needed. Serial (it may make a tile).
  T* at(const VecI<Dim>& c) {
    const auto [tile, local] = locate(c);
    return make_tile(tile) + static_cast<std::size_t>(local) * Stride;
  }
  /// The Stride values of point c, null where no tile holds c (every value the background).
  /// Safe on several threads once the tiles are made.
  T* find(const VecI<Dim>& c) {
    const auto [tile, local] = locate(c);
    T* data = tiles_[tile].get();
    return data ? data + static_cast<std::size_t>(local) * Stride : nullptr;
  }
  const T* find(const VecI<Dim>& c) const { return const_cast<TiledLattice*>(this)->find(c); }
  /// Value s of point c (the background where no tile holds c).
  T value(const VecI<Dim>& c, int s = 0) const {
    const T* p = find(c);
    return p ? p[s] : background_;
  }

  /// f(coord, values) for every point of every tile made (values: Stride entries), tiles in
  /// tile-index order and points in lattice order within a tile; points of a partial tile at
  /// the lattice's upper end that lie outside the lattice are skipped.
  template <class F>
  void for_each_point(F&& f) const {
    for (int tile = 0; tile < num_tile_slots(); ++tile) for_each_point_in_tile(tile, f);
  }

  /// Slots of the tile table (made or not): tile indices run over [0, num_tile_slots()).
  int num_tile_slots() const { return static_cast<int>(tiles_.size()); }
  /// Whether tile `tile` is made.
  bool has_tile(int tile) const { return tiles_[tile] != nullptr; }
  /// f(coord, values) for every point of one made tile (nothing for an absent one), points in
  /// lattice order, those outside the lattice skipped. Distinct tiles may run on several threads.
  template <class F>
  void for_each_point_in_tile(int tile, F&& f) const {
    const T* data = tiles_[tile].get();
    if (!data) return;
    const VecI<Dim> origin = kTile * lattice_coord<Dim>(tile, tile_dims_);
    for (int local = 0; local < kTilePoints; ++local) {
      const VecI<Dim> c = origin + lattice_coord<Dim>(local, VecI<Dim>::Constant(kTile));
      if ((c.array() >= dims_.array()).any()) continue;
      f(static_cast<const VecI<Dim>&>(c), data + static_cast<std::size_t>(local) * Stride);
    }
  }

  /// f(coord, values) as above, the values writable. Distinct tiles may run on several threads.
  template <class F>
  void for_each_point_in_tile(int tile, F&& f) {
    T* data = tiles_[tile].get();
    if (!data) return;
    const VecI<Dim> origin = tile_origin(tile);
    for (int local = 0; local < kTilePoints; ++local) {
      const VecI<Dim> c = origin + lattice_coord<Dim>(local, VecI<Dim>::Constant(kTile));
      if ((c.array() >= dims_.array()).any()) continue;
      f(static_cast<const VecI<Dim>&>(c), data + static_cast<std::size_t>(local) * Stride);
    }
  }
  /// The point coordinates of the lowest point of tile `tile` (made or not).
  VecI<Dim> tile_origin(int tile) const { return kTile * lattice_coord<Dim>(tile, tile_dims_); }

  /// Value s of every point as one dense vector in lattice_index order (the background where no
  /// tile is): for code that reads whole-lattice vectors.
  void to_dense(VectorX& out, int s = 0) const {
    out.setConstant(dims_.prod(), static_cast<double>(background_));
    for_each_point([&](const VecI<Dim>& c, const T* v) {
      out[lattice_index<Dim>(c, dims_)] = static_cast<double>(v[s]);
    });
  }

 private:
  /// fn(tile slot) for every tile holding a point of the box [lo, hi] (point coordinates,
  /// clamped to the lattice; an empty box visits none), x fastest.
  template <class Fn>
  void for_each_tile_in_box(VecI<Dim> lo, VecI<Dim> hi, Fn&& fn) const {
    for (int a = 0; a < Dim; ++a) {
      lo[a] = std::max(lo[a], 0);
      hi[a] = std::min(hi[a], dims_[a] - 1);
      if (lo[a] > hi[a]) return;
      lo[a] /= kTile;
      hi[a] /= kTile;
    }
    VecI<Dim> t = lo;
    while (true) {
      fn(lattice_index<Dim>(t, tile_dims_));
      int a = 0;
      for (; a < Dim; ++a) {
        if (++t[a] <= hi[a]) break;
        t[a] = lo[a];
      }
      if (a == Dim) return;
    }
  }

  std::pair<int, int> locate(const VecI<Dim>& c) const {
    VecI<Dim> t, l;
    for (int a = 0; a < Dim; ++a) {
      t[a] = c[a] / kTile;
      l[a] = c[a] - t[a] * kTile;
    }
    return {lattice_index<Dim>(t, tile_dims_), lattice_index<Dim>(l, VecI<Dim>::Constant(kTile))};
  }
  T* make_tile(int tile) {
    std::unique_ptr<T[]>& data = tiles_[tile];
    if (!data) {
      std::vector<std::unique_ptr<T[]>> block;
      Pool::instance().take(1, block);
      if (block.empty())
        data.reset(new T[static_cast<std::size_t>(kTilePoints) * Stride]);
      else
        data = std::move(block.front());
      fill_tile(data.get());
      ++num_tiles_;
    }
    return data.get();
  }

  VecI<Dim> dims_ = VecI<Dim>::Zero(), tile_dims_ = VecI<Dim>::Zero();
  T background_{};
  std::vector<std::unique_ptr<T[]>> tiles_;
  int num_tiles_ = 0;
};

}  // namespace monolith
