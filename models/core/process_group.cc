// Copyright 2026 The tactfunc Authors.
#include "models/core/process_group.h"

#include <string>

namespace tactfunc {

bool ProcessGroup::AnyOf(bool mine) const {
  if (size() == 1) return mine;
  for (const Bytes& flag : AllGather(Bytes{static_cast<std::uint8_t>(mine ? 1 : 0)})) {
    if (!flag.empty() && flag[0] != 0) return true;
  }
  return false;
}

void ProcessGroup::Share(std::int64_t count, int rank, std::int64_t* begin,
                         std::int64_t* end) const {
  *begin = count * rank / size();
  *end = count * (rank + 1) / size();
}

std::vector<std::int64_t> ProcessGroup::OwnItems(std::int64_t count) const {
  std::vector<std::int64_t> items;
  for (std::int64_t i = rank(); i < count; i += size()) items.push_back(i);
  return items;
}

std::vector<Bytes> ProcessGroup::GatherItems(std::int64_t count,
                                             const std::vector<Bytes>& mine) const {
  const std::size_t own = OwnItems(count).size();
  if (mine.size() != own) {
    throw std::runtime_error("ProcessGroup::GatherItems: process " + std::to_string(rank()) +
                             " passed " + std::to_string(mine.size()) + " results for its " +
                             std::to_string(own) + " items");
  }
  if (size() == 1) return mine;
  // One message per process: its items' buffers, each behind its length.
  ByteWriter message;
  message.Put<std::int64_t>(count);
  for (const Bytes& item : mine) {
    message.Put<std::uint64_t>(item.size());
    message.bytes().insert(message.bytes().end(), item.begin(), item.end());
  }
  const std::vector<Bytes> all = AllGather(message.bytes());
  std::vector<Bytes> items(static_cast<std::size_t>(count));
  for (int r = 0; r < size(); ++r) {
    ByteReader reader(all[r]);
    // Processes that selected other items (other data at the same path) must not mix.
    if (const std::int64_t theirs = reader.Get<std::int64_t>(); theirs != count) {
      throw std::runtime_error("process " + std::to_string(r) + " of " + std::to_string(size()) +
                               " has " + std::to_string(theirs) + " items to share, process " +
                               std::to_string(rank()) + " has " + std::to_string(count) +
                               " (do all processes read the same data and options?)");
    }
    for (std::int64_t i = r; i < count; i += size()) {
      Bytes& item = items[static_cast<std::size_t>(i)];
      item.resize(static_cast<std::size_t>(reader.Get<std::uint64_t>()));
      reader.GetBytes(item.data(), item.size());
    }
    if (!reader.AtEnd()) {
      throw std::runtime_error("ProcessGroup::GatherItems: process " + std::to_string(r) +
                               " sent more results than it owns items");
    }
  }
  return items;
}

namespace {

class Single final : public ProcessGroup {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  std::vector<Bytes> AllGather(const Bytes& mine) const override { return {mine}; }
  void Broadcast(Bytes*) const override {}
};

}  // namespace

const ProcessGroup& SingleProcess() {
  static const Single single;
  return single;
}

}  // namespace tactfunc
