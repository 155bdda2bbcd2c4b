// Copyright 2026 The tactfunc Authors.
//
// ProcessGroup: the processes that share one run (data parallelism across machines,
// docs/SCALING.md), as the libraries see them -- a rank, a size and two collectives on
// byte buffers. The libraries never link MPI: the tactfunc program implements this
// interface with MPI (apps/distributed.h) and passes it to TrunkTrainer and
// LatentEncoder through their Options; SingleProcess() is the group of this process
// alone, what a null pointer there means.
//
// Collectives: every process of the group calls them in the same order with the same
// kind of arguments; a process that fails between two collectives leaves the others
// waiting, so the program ends the whole group on an error (apps/distributed.h).
//
// ByteWriter / ByteReader pack the collectives' payloads: plain values and float arrays
// appended in one order and read back in the same order (the processes of a group run
// the same build, so the byte layout is the same everywhere).
#ifndef TACTFUNC_MODELS_CORE_PROCESS_GROUP_H_
#define TACTFUNC_MODELS_CORE_PROCESS_GROUP_H_

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace tactfunc {

using Bytes = std::vector<std::uint8_t>;

class ProcessGroup {
 public:
  virtual ~ProcessGroup() = default;

  // This process's index in [0, size()); rank 0 writes the outputs.
  virtual int rank() const = 0;
  virtual int size() const = 0;

  // Every process passes its buffer (sizes may differ); each receives all of them,
  // element r being rank r's.
  virtual std::vector<Bytes> AllGather(const Bytes& mine) const = 0;
  // Rank 0's *data replaces every other process's (any size).
  virtual void Broadcast(Bytes* data) const = 0;

  // True on every process if `mine` is true on any (one AllGather).
  bool AnyOf(bool mine) const;
  // Rank `rank`'s contiguous share [*begin, *end) of `count` items:
  // [count rank / size, count (rank + 1) / size), so the shares cover [0, count) in
  // rank order.
  void Share(std::int64_t count, int rank, std::int64_t* begin, std::int64_t* end) const;

  // Per-item work spread over the processes (recon, eval, bench posterior): of `count`
  // items, this process computes OwnItems(count) -- every size()-th from rank(), so that
  // items listed in runs (a dataset's frames tool by tool) spread their runs over the
  // processes -- and passes one buffer per own item, in that order, to GatherItems,
  // which returns every item's buffer in item order [0, count), on every process (one
  // AllGather). Throws std::runtime_error if a process passed another number of buffers
  // than it owns items, or if the processes passed different counts.
  std::vector<std::int64_t> OwnItems(std::int64_t count) const;
  std::vector<Bytes> GatherItems(std::int64_t count, const std::vector<Bytes>& mine) const;
};

// The group of this process alone: rank 0 of 1; AllGather returns {mine}, Broadcast
// does nothing.
const ProcessGroup& SingleProcess();

class ByteWriter {
 public:
  template <typename T>
  void Put(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>, "ByteWriter::Put: plain values only");
    Append(&value, sizeof(T));
  }
  void PutFloats(const float* values, std::size_t count) {
    Put<std::uint64_t>(count);
    Append(values, count * sizeof(float));
  }
  void PutString(const std::string& text) {
    Put<std::uint64_t>(text.size());
    Append(text.data(), text.size());
  }
  Bytes& bytes() { return bytes_; }

 private:
  void Append(const void* data, std::size_t size) {
    const auto* p = static_cast<const std::uint8_t*>(data);
    bytes_.insert(bytes_.end(), p, p + size);
  }
  Bytes bytes_;
};

// Reads what a ByteWriter wrote; throws std::runtime_error past the end or on a float
// array of another length than expected.
class ByteReader {
 public:
  explicit ByteReader(const Bytes& bytes) : bytes_(bytes) {}
  template <typename T>
  T Get() {
    static_assert(std::is_trivially_copyable_v<T>, "ByteReader::Get: plain values only");
    T value;
    Copy(&value, sizeof(T));
    return value;
  }
  // The float array's length, then its values into `out` (which must hold that many).
  std::size_t FloatCount() { return static_cast<std::size_t>(Get<std::uint64_t>()); }
  void GetFloats(float* out, std::size_t count) { Copy(out, count * sizeof(float)); }
  void GetBytes(std::uint8_t* out, std::size_t count) { Copy(out, count); }
  std::string GetString() {
    std::string text(static_cast<std::size_t>(Get<std::uint64_t>()), '\0');
    Copy(text.data(), text.size());
    return text;
  }
  bool AtEnd() const { return offset_ == bytes_.size(); }

 private:
  void Copy(void* out, std::size_t size) {
    if (size > bytes_.size() - offset_) {
      throw std::runtime_error("ProcessGroup: a message from another process ended after " +
                               std::to_string(bytes_.size()) + " bytes, " +
                               std::to_string(offset_ + size) + " expected");
    }
    if (size > 0) std::memcpy(out, bytes_.data() + offset_, size);
    offset_ += size;
  }
  const Bytes& bytes_;
  std::size_t offset_ = 0;
};

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_CORE_PROCESS_GROUP_H_
