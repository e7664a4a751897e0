#pragma once
// vnr::Opaque<T>: an optional value held on the heap, so that a public header can declare a member of an
// internal type T it only names (`struct T;`). Code that touches the value includes T's header; copying,
// assigning and destroying need T complete only where they happen (the owner defines its special members
// out of line, where T is complete).
#include <memory>
#include <optional>
#include <utility>

namespace vnr {

template <class T>
class Opaque {
public:
  Opaque() = default;
  ~Opaque() = default;
  Opaque(Opaque&&) noexcept = default;
  Opaque& operator=(Opaque&&) noexcept = default;
  Opaque(const Opaque& o) : p_(o.p_ ? std::make_unique<T>(*o.p_) : nullptr) {}
  Opaque& operator=(const Opaque& o) {
    if (this != &o) p_ = o.p_ ? std::make_unique<T>(*o.p_) : nullptr;
    return *this;
  }
  Opaque& operator=(T value) {
    p_ = std::make_unique<T>(std::move(value));
    return *this;
  }
  Opaque& operator=(std::optional<T> value) {
    p_ = value ? std::make_unique<T>(std::move(*value)) : nullptr;
    return *this;
  }

  template <class... Args>
  T& emplace(Args&&... args) {
    p_ = std::make_unique<T>(std::forward<Args>(args)...);
    return *p_;
  }

  bool has_value() const { return p_ != nullptr; }
  explicit operator bool() const { return p_ != nullptr; }
  T& operator*() { return *p_; }
  const T& operator*() const { return *p_; }
  T* operator->() { return p_.get(); }
  const T* operator->() const { return p_.get(); }
  // The value, or null when there is none.
  T* get() { return p_.get(); }
  const T* get() const { return p_.get(); }
  void reset() { p_.reset(); }

private:
  std::unique_ptr<T> p_;
};

}  // namespace vnr
