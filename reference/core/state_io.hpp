#pragma once
/// \file state_io.hpp
/// Plain bytes in and out of a simulation's state, for checkpoints. A state is listed once, as
/// a member template `template <class Archive> void state_fields(Archive& a)` that calls
/// a(field) for every field in a fixed order; StateWriter appends each field's bytes and
/// StateReader reads them back into the same fields, so saving and loading can never list the
/// fields differently. Numbers are stored as their in-memory bytes (the same build on the same
/// machine reads them back bit for bit; the file layer checks the build). Files, headers and
/// checksums belong to the application (reference/app/checkpoint.hpp).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "reference/core/errors.hpp"

namespace monolith {

namespace state_detail {
/// Types whose vectors are stored as one block of bytes: numbers (not bool) and fixed-size
/// Eigen matrices of numbers (Vec<Dim>, Mat<Dim>: contiguous, no pointers).
template <class T, class = void>
struct is_block : std::bool_constant<std::is_arithmetic_v<T> && !std::is_same_v<T, bool>> {};
template <class T>
struct is_block<T, std::enable_if_t<std::is_base_of_v<Eigen::MatrixBase<T>, T>>>
    : std::bool_constant<T::SizeAtCompileTime != Eigen::Dynamic &&
                         std::is_arithmetic_v<typename T::Scalar> &&
                         sizeof(T) == sizeof(typename T::Scalar) * T::SizeAtCompileTime> {};
}  // namespace state_detail

/// Appends fields to a byte buffer (see the file comment).
class StateWriter {
 public:
  static constexpr bool loading = false;

  template <class T>
  std::enable_if_t<std::is_arithmetic_v<T>> operator()(const T& v) {
    raw(&v, sizeof v);
  }
  void operator()(const bool& v) {
    const std::uint8_t b = v ? 1 : 0;
    raw(&b, 1);
  }
  void operator()(const std::string& s) {
    size(s.size());
    raw(s.data(), s.size());
  }
  template <class S, int R, int C, int O, int MR, int MC>
  void operator()(const Eigen::Matrix<S, R, C, O, MR, MC>& m) {
    static_assert(std::is_arithmetic_v<S>);
    size(static_cast<std::uint64_t>(m.rows()));
    size(static_cast<std::uint64_t>(m.cols()));
    raw(m.data(), sizeof(S) * static_cast<std::size_t>(m.size()));
  }
  void operator()(const Eigen::Quaterniond& q) { (*this)(q.coeffs()); }
  template <class T, class U>
  void operator()(const std::pair<T, U>& p) {
    (*this)(p.first);
    (*this)(p.second);
  }
  template <class T, class A>
  void operator()(const std::vector<T, A>& v) {
    size(v.size());
    if constexpr (state_detail::is_block<T>::value) {
      raw(v.data(), sizeof(T) * v.size());
    } else {
      for (const auto& e : v) (*this)(e);
    }
  }
  /// Structs list their own fields: a.fields(x) calls x.state_fields(a).
  template <class T>
  auto operator()(const T& v) -> decltype(const_cast<T&>(v).state_fields(*this), void()) {
    const_cast<T&>(v).state_fields(*this);
  }

  const std::vector<char>& bytes() const { return bytes_; }
  std::vector<char> take() { return std::move(bytes_); }

 private:
  void size(std::uint64_t n) { raw(&n, sizeof n); }
  void raw(const void* p, std::size_t n) {
    const char* c = static_cast<const char*>(p);
    bytes_.insert(bytes_.end(), c, c + n);
  }
  std::vector<char> bytes_;
};

/// Reads fields back in the order StateWriter wrote them; throws InputError (naming `what`) on
/// bytes that end early, sizes that do not fit the rest of the data, or left-over bytes
/// (finish()).
class StateReader {
 public:
  static constexpr bool loading = true;

  /// Reads from `bytes`, which must outlive the reader (it keeps pointers into them).
  StateReader(const std::vector<char>& bytes, std::string what)
      : data_(bytes.data()), end_(bytes.data() + bytes.size()), what_(std::move(what)) {}
  /// A temporary would be gone before the first read (the ASan suite found a test doing it).
  StateReader(std::vector<char>&& bytes, std::string what) = delete;

  template <class T>
  std::enable_if_t<std::is_arithmetic_v<T>> operator()(T& v) {
    raw(&v, sizeof v);
  }
  void operator()(bool& v) {
    std::uint8_t b = 0;
    raw(&b, 1);
    if (b > 1) fail("a flag that is neither 0 nor 1");
    v = b == 1;
  }
  void operator()(std::string& s) {
    const std::uint64_t n = size(1);
    s.assign(data_, data_ + n);
    data_ += n;
  }
  template <class S, int R, int C, int O, int MR, int MC>
  void operator()(Eigen::Matrix<S, R, C, O, MR, MC>& m) {
    const std::uint64_t rows = size(0), cols = size(0);
    if ((R != Eigen::Dynamic && rows != static_cast<std::uint64_t>(R)) ||
        (C != Eigen::Dynamic && cols != static_cast<std::uint64_t>(C)))
      fail("a matrix of the wrong shape");
    if (cols != 0 && rows > static_cast<std::uint64_t>(end_ - data_) / sizeof(S) / cols)
      fail("a matrix larger than the data");
    m.resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols));
    raw(m.data(), sizeof(S) * static_cast<std::size_t>(m.size()));
  }
  void operator()(Eigen::Quaterniond& q) { (*this)(q.coeffs()); }
  template <class T, class U>
  void operator()(std::pair<T, U>& p) {
    (*this)(p.first);
    (*this)(p.second);
  }
  template <class T, class A>
  void operator()(std::vector<T, A>& v) {
    if constexpr (state_detail::is_block<T>::value) {
      v.resize(size(sizeof(T)));
      raw(v.data(), sizeof(T) * v.size());
    } else {
      v.resize(size(1));
      for (auto& e : v) (*this)(e);
    }
  }
  template <class T>
  auto operator()(T& v) -> decltype(v.state_fields(*this), void()) {
    v.state_fields(*this);
  }

  /// Throws unless every byte was read.
  void finish() const {
    if (data_ != end_) fail("bytes left over after the last field");
  }
  [[noreturn]] void fail(const std::string& why) const {
    throw InputError(what_ + ": malformed simulation state (" + why +
                     "; a checkpoint written by this build for this scene is needed)");
  }

 private:
  /// A count of elements of at least `element` bytes each that must fit the remaining data.
  std::uint64_t size(std::size_t element) {
    std::uint64_t n = 0;
    raw(&n, sizeof n);
    if (element > 0 && n > static_cast<std::uint64_t>(end_ - data_) / element) fail("a length beyond the end of the data");
    return n;
  }
  void raw(void* p, std::size_t n) {
    if (static_cast<std::size_t>(end_ - data_) < n) fail("the data ends early");
    if (n) std::memcpy(p, data_, n);
    data_ += n;
  }
  const char* data_;
  const char* end_;
  std::string what_;
};

}  // namespace monolith
