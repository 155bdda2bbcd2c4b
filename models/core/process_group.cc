// Copyright 2026 The tactfunc Authors.
#include "models/core/process_group.h"

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
