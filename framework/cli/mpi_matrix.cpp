// exid — `mpirun -np N exid matrix ...`: when the program runs under an MPI launcher and exid
// was built with MPI, rank r runs shard r/N of the matrix into its own database; rank 0 then
// gathers every shard into DIR/results.sqlite. Without MPI (or without a launcher) nothing here
// is used and the matrix runs in one process.
#include <cstdlib>

#include "commands.hpp"

#ifdef EXID_WITH_MPI
#include <mpi.h>
#endif

namespace exid::cli {

bool underMpiLauncher() {
  return std::getenv("OMPI_COMM_WORLD_SIZE") != nullptr || std::getenv("PMI_SIZE") != nullptr ||
         std::getenv("PMIX_RANK") != nullptr;
}

#ifdef EXID_WITH_MPI
bool mpiAvailable() { return true; }

MpiSession::MpiSession() {
  int inited = 0;
  MPI_Initialized(&inited);
  if (!inited) MPI_Init(nullptr, nullptr);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  active = true;
}
MpiSession::~MpiSession() {
  if (active) MPI_Finalize();
}
void MpiSession::barrier() { MPI_Barrier(MPI_COMM_WORLD); }
int MpiSession::sumInt(int v) {
  int out = 0;
  MPI_Allreduce(&v, &out, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD);
  return out;
}
#else
bool mpiAvailable() { return false; }
MpiSession::MpiSession() = default;
MpiSession::~MpiSession() = default;
void MpiSession::barrier() {}
int MpiSession::sumInt(int v) { return v; }
#endif

}  // namespace exid::cli
