// Copyright 2026 The tactfunc Authors.
//
// The processes of one run of the program (docs/SCALING.md). `mpirun -np N tactfunc
// train|encode|recon|eval|bench posterior ...` starts N processes; in a build with MPI
// (CMake found it: TACTFUNC_WITH_MPI) they join one ProcessGroup over MPI_COMM_WORLD,
// which the commands hand to TrunkTrainer, LatentEncoder, ReconstructionEvaluator and
// TableEvaluation (bench posterior shares out its frames itself). Everything else sees
// the group of this process alone, so the commands hold no #ifdef:
//
//   StartProcesses(command)  main(), after the flags are parsed
//   Processes()              the group (MPI or SingleProcess())
//   ReportError(line)        main()'s error line, from any process
//   AbortProcesses(code)     main(), after an error in a run of several processes
//   FinishProcesses()        main(), at a normal end (also at exit)
//
// Only rank 0 speaks: the other processes' stdout and stderr go to /dev/null once they
// joined (their errors still reach the terminal through ReportError). A process that
// fails ends the whole group (MPI_Abort): the others would otherwise wait for it in the
// next collective forever. Files are written by rank 0 only, atomically, so an ended
// run leaves its last checkpoint intact for --resume.
#ifndef TACTFUNC_APPS_DISTRIBUTED_H_
#define TACTFUNC_APPS_DISTRIBUTED_H_

#include <string>

#include "models/core/process_group.h"

namespace tactfunc::apps {

// True if this build links MPI.
bool BuiltWithMpi();

// The process count and this process's rank that a launcher set in the environment
// (Open MPI's OMPI_COMM_WORLD_SIZE / _RANK, or PMI_SIZE / PMI_RANK of MPICH's hydra and
// Slurm); 1 and 0 when none did.
int LaunchedProcessCount();
int LaunchedRank();

// Joins the processes of the run for `command` (the subcommand path: "encode", "bench
// posterior"). Launched as several processes, `train`, `encode`, `recon`, `eval` and
// `bench posterior` join the MPI group; any other command, or any command
// of a build without MPI, throws UsageError (every process throws; only rank 0 should
// print it, see ReportError). Launched as one process it does nothing.
void StartProcesses(const std::string& command);

// The group StartProcesses joined, or SingleProcess().
const ProcessGroup& Processes();

// Throws std::runtime_error on every process of `group` unless all of them read the
// same bytes at `path` (or all find no file there): files that rank 0 writes and every
// process reads back (training checkpoints) must be on a file system they share.
void RefuseUnsharedFile(const ProcessGroup& group, const std::string& path);

// Writes `line` (and a newline) to the terminal's stderr: rank 0 at once; another
// process after a grace period (so that an error every process hits is printed once,
// by rank 0, whose AbortProcesses ends the others first), with its rank appended.
void ReportError(const std::string& line);

// After an error in a run of several processes: ends all of them with exit code `code`
// (MPI_Abort). Returns at once when this process runs alone.
void AbortProcesses(int code);

// Leaves the MPI group (MPI_Finalize) if StartProcesses joined one; later calls do
// nothing.
void FinishProcesses();

}  // namespace tactfunc::apps

#endif  // TACTFUNC_APPS_DISTRIBUTED_H_
