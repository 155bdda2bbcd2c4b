// Copyright 2026 The tactfunc Authors.
//
// LD_PRELOAD shim for mpi_cli_test, through MPI's profiling interface: the process of
// rank $TACTFUNC_TEST_DIE_RANK kills itself with SIGKILL (as a crashed machine would
// end it) on entering its $TACTFUNC_TEST_DIE_AT-th MPI_Allgatherv, the collective
// through which the commands that run as several processes exchange their work. Every
// other call goes straight to the real one (PMPI_Allgatherv).
#include <mpi.h>
#include <signal.h>

#include <cstdlib>

extern "C" int MPI_Allgatherv(const void* send, int count, MPI_Datatype send_type, void* receive,
                              const int counts[], const int offsets[], MPI_Datatype receive_type,
                              MPI_Comm comm) {
  static int calls = 0;
  const char* rank = std::getenv("TACTFUNC_TEST_DIE_RANK");
  const char* at = std::getenv("TACTFUNC_TEST_DIE_AT");
  int my_rank = -1;
  PMPI_Comm_rank(comm, &my_rank);
  if (rank != nullptr && at != nullptr && std::atoi(rank) == my_rank && ++calls == std::atoi(at)) {
    raise(SIGKILL);
  }
  return PMPI_Allgatherv(send, count, send_type, receive, counts, offsets, receive_type, comm);
}
