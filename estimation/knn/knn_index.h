// Copyright 2026 The tactfunc Authors.
//
// k-nearest-neighbour search over latent codes, the faiss way (Sec. III-C of "Tactile
// Functasets": the k nearest functaset latents of a new frame's latent, by Euclidean
// distance, give a fast estimate and a warm start).
//
// KnnIndex is a small abstract core, as faiss::Index:
//   Add(vectors, n)                          appends n vectors; labels are 0, 1, 2, ...
//                                            in order of addition (as faiss::IndexFlat)
//   Search(queries, n, k, distances, labels) the k nearest stored vectors of each query
//   size(), dim(), Save(path), KnnIndex::Load(path)
// with two implementations:
//   BruteForceKnnIndex  exact; the reference the tests check FLANN against. Batched:
//                       ||q - x||^2 = ||q||^2 - 2 q.x + ||x||^2 with one float GEMM per
//                       block of queries, then the distances of the selected candidates
//                       recomputed directly (in double) so that the output is exact and
//                       free of the expansion's cancellation error.
//   FlannKnnIndex       FLANN 1.9 (randomized kd-forest, hierarchical k-means,
//                       autotuned, or linear), approximate. FLANN's headers are only
//                       included by knn_index.cc (see internal/flann_include.h).
//
// Buffers (documented once; all row-major, caller-allocated):
//   vectors    n x d float  (one vector per row)
//   queries    n x d float
//   distances  n x k float  SQUARED Euclidean distances, ascending along each row
//   labels     n x k int64  the stored vectors' labels; where fewer than k neighbours
//                           exist (k > size(), or an approximate index found fewer) the
//                           row is padded with label -1 and distance +infinity, as faiss
//
// Errors (three tiers): a bad Options throws std::invalid_argument from the
// constructor with the IsValid message; a bad buffer (d mismatch, n < 0, k < 1, NaN
// or infinite entries in vectors) throws std::invalid_argument quoting the shapes or
// the offending row; a corrupt or foreign file throws TensorFileError
// (models/core/tensor_file.h) naming the file.
//
// Thread safety: Search is const and safe to call concurrently; Add is not (as faiss).
#ifndef TACTFUNC_ESTIMATION_KNN_KNN_INDEX_H_
#define TACTFUNC_ESTIMATION_KNN_KNN_INDEX_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace tactfunc {

class TensorFile;

class KnnIndex {
 public:
  explicit KnnIndex(int dim);
  virtual ~KnnIndex();
  KnnIndex(const KnnIndex&) = delete;
  KnnIndex& operator=(const KnnIndex&) = delete;

  // Dimension d of every vector. >= 1.
  int dim() const { return dim_; }
  // Number of vectors stored.
  std::int64_t size() const { return static_cast<std::int64_t>(data_.size()) / dim_; }
  // The stored vectors, size() x d row-major (label i is row i).
  const float* data() const { return data_.data(); }

  // Appends n vectors (n x d). n = 0 is a no-op. Throws std::invalid_argument for
  // n < 0, a null pointer with n > 0, or a non-finite entry (naming its row and column).
  void Add(const float* vectors, std::int64_t n);

  // For each of the n queries (n x d), its k nearest stored vectors: distances and
  // labels n x k (see the header comment). k >= 1; n >= 0. Throws
  // std::invalid_argument on k < 1, n < 0 or null pointers with n > 0. A query with a
  // NaN entry gets a row of -1 / +infinity (nothing is near it).
  virtual void Search(const float* queries, std::int64_t n, int k, float* distances,
                      std::int64_t* labels) const = 0;

  // "brute_force" or "flann".
  virtual std::string TypeName() const = 0;
  // One line for logs: type, size, dim and the build parameters.
  virtual std::string Describe() const = 0;

  // Saves the index atomically (models/core/atomic_file.h) as a TensorFile of kind
  // "knn_index": meta {"format": "tactfunc-knn-index", "version": 1, "type", "dim",
  // "size", "params": {...}} and the tensor "vectors" (float32, size x d). FLANN's own
  // binary blob (save_index) is NOT stored: Load rebuilds the index from the vectors
  // with the stored parameters and seed, which gives the same index (and so the same
  // search results) because builds are deterministic given the seed (see
  // FlannKnnIndex). An autotuned index stores the parameters the tuning chose, so the
  // reloaded index is that index, without re-tuning.
  void Save(const std::string& path) const;
  // Throws TensorFileError naming the file and what is wrong.
  static std::unique_ptr<KnnIndex> Load(const std::string& path);
  // Load from the file's bytes; `source` names them in messages (a path).
  static std::unique_ptr<KnnIndex> Parse(const std::string& bytes, const std::string& source);

 protected:
  // Called after vectors were appended to data_ (already validated).
  virtual void OnAdd(std::int64_t first_new_row) = 0;
  // Implementation parameters as a JSON object text, stored by Save.
  virtual std::string ParamsJson() const = 0;
  // Checks the Search arguments (throws) and pads the outputs for n queries when k
  // exceeds `available`; returns min(k, available).
  int CheckSearch(const float* queries, std::int64_t n, int k, float* distances,
                  std::int64_t* labels) const;

  // Exact search over data_ (as BruteForceKnnIndex::Search, after CheckSearch).
  void ExactSearch(const float* queries, std::int64_t n, int k, int available,
                   float* distances, std::int64_t* labels) const;

  std::vector<float> data_;
  std::vector<float> squared_norms_;  // size(), ||x_i||^2

 private:
  int dim_;
};

// ---- Exact reference ------------------------------------------------------------------
class BruteForceKnnIndex : public KnnIndex {
 public:
  // Throws std::invalid_argument for dim < 1.
  explicit BruteForceKnnIndex(int dim);

  void Search(const float* queries, std::int64_t n, int k, float* distances,
              std::int64_t* labels) const override;
  std::string TypeName() const override { return "brute_force"; }
  std::string Describe() const override;

 protected:
  void OnAdd(std::int64_t /*first_new_row*/) override {}
  std::string ParamsJson() const override { return "{}"; }
};

// ---- FLANN --------------------------------------------------------------------------
class FlannKnnIndex : public KnnIndex {
 public:
  enum class Algorithm {
    kKdForest,   // randomized kd-trees searched together (FLANN's KDTreeIndex)
    kKMeans,     // hierarchical k-means tree (KMeansIndex)
    kAutotuned,  // FLANN chooses the algorithm and parameters for target_precision
    kLinear,     // exhaustive (LinearIndex); exact, for checks
  };

  // Build parameters (faiss: the index's constructor arguments).
  struct Options {
    Algorithm algorithm = Algorithm::kKdForest;
    // kd-forest: number of randomized trees. >= 1. FLANN's default is 4; 4 trees
    // on 30,000 x 512 build in 0.27 s and take 7.5 MB (docs/BUILD.md).
    int trees = 4;
    // k-means: branching factor of the tree. >= 2. FLANN's default 32.
    int branching = 32;
    // k-means: Lloyd iterations per level; -1 = until convergence. FLANN's default 11.
    int kmeans_iterations = 11;
    // k-means: fraction of leaves checked before the tree is descended again, in
    // (0, 1]. FLANN's default 0.2.
    float cb_index = 0.2f;
    // autotuned: the recall@1 FLANN tunes for, in (0, 1]. FLANN's default 0.8; 0.9
    // here because a k-NN warm start wants the right neighbourhood.
    float target_precision = 0.9f;
    // autotuned: weight of build time against search time, >= 0 (FLANN's 0.01), and
    // of memory, >= 0 (FLANN's 0), and the fraction of the data sampled for tuning,
    // in (0, 1] (FLANN's 0.1).
    float build_weight = 0.01f;
    float memory_weight = 0.0f;
    float sample_fraction = 0.1f;
    // Seed of every random choice FLANN makes while building (tree split dimensions,
    // shuffles, k-means centres): the same vectors, options and seed give the same
    // index. Autotuning also times trial searches, so WHICH parameters it picks can
    // vary between runs; the index built from them is then deterministic.
    std::uint32_t seed = 0;

    bool IsValid(std::string* error) const;
  };

  // Per-query parameters (faiss: SearchParameters).
  struct SearchParams {
    // Leaves (kd-forest) or points (k-means) examined per query; -1 = all, which runs
    // the exact search of BruteForceKnnIndex instead (FLANN's own exact kd-forest
    // search prints a warning per query). >= 1 or -1. recall@8 0.35 / 0.49 / 0.65 at
    // 64 / 128 / 256 checks on 512-d latents near a 16-d subspace (docs/BUILD.md; d =
    // 64: docs/FITTING.md). An autotuned index ignores this and uses the checks it tuned.
    int checks = 256;
    // Approximation slack: a branch is pruned if it cannot hold a point closer than
    // (1 + eps) times the current k-th distance. >= 0. 0 is FLANN's default.
    float eps = 0.0f;
    // (No thread count: knn_index.cc is not compiled with OpenMP, so FLANN's
    // parallel search would be single-threaded anyway; parallelise over frames.)

    bool IsValid(std::string* error) const;
  };

  // Throws std::invalid_argument for dim < 1 or invalid options. (Two constructors, not a
  // default argument: a nested struct's default member initializers cannot be used in
  // a default argument inside the enclosing class.)
  FlannKnnIndex(int dim, const Options& options);
  FlannKnnIndex(int dim, const Options& options, const SearchParams& search_params);
  ~FlannKnnIndex() override;

  const Options& options() const { return options_; }
  const SearchParams& search_params() const { return search_params_; }
  void set_search_params(const SearchParams& params);  // throws if !IsValid

  // Search with the index's search_params().
  void Search(const float* queries, std::int64_t n, int k, float* distances,
              std::int64_t* labels) const override;
  // Search with explicit per-query parameters.
  void Search(const float* queries, std::int64_t n, int k, float* distances,
              std::int64_t* labels, const SearchParams& params) const;

  std::string TypeName() const override { return "flann"; }
  std::string Describe() const override;

  // What the build resolved to: for kAutotuned, the algorithm and parameters FLANN
  // chose, as JSON ({"algorithm": "kd_forest", "trees": 8, "checks": 96, ...}); the
  // options as given otherwise.
  std::string ResolvedParamsJson() const;

  // Used by KnnIndex::Load: rebuilds from stored parameters.
  static std::unique_ptr<FlannKnnIndex> FromParamsJson(int dim, const std::string& json,
                                                       const std::string& source);

 protected:
  // Rebuilds the FLANN index over all stored vectors (FLANN keeps pointers into
  // data_, and a full rebuild keeps the index a function of (vectors, options, seed)
  // alone). Add vectors in one batch: each Add costs a full build.
  void OnAdd(std::int64_t first_new_row) override;
  std::string ParamsJson() const override { return ResolvedParamsJson(); }

 private:
  struct Impl;
  Options options_;
  SearchParams search_params_;
  std::unique_ptr<Impl> impl_;
};

const char* ToString(FlannKnnIndex::Algorithm algorithm);
// "kd_forest", "kmeans", "autotuned", "linear".
bool FlannAlgorithmFromString(const std::string& name, FlannKnnIndex::Algorithm* algorithm);

// recall@k of `approx` against `exact` on n queries (n x d): the fraction of the exact
// k nearest labels that approx also returns among its k, over all queries (the
// "intersection" measure of faiss' benchmarks). In [0, 1]; 1 when n = 0. Throws
// std::invalid_argument if the two indexes differ in dim or size.
double Recall(const KnnIndex& approx, const KnnIndex& exact, const float* queries,
              std::int64_t n, int k);

// ---- Construction ---------------------------------------------------------------------
// The one way the library and the commands make an index over a set of vectors (the
// latents of a functaset, the pixels of a baseline), in memory or cached in a file.

// Vectors, one per row (n x d, row-major): the layout of Functaset::LatentMatrix.
using KnnVectors = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

struct KnnIndexOptions {
  // "brute_force" (default: exact) or a FLANN algorithm, as FlannAlgorithmFromString
  // names it ("kd_forest", "kmeans", "autotuned", "linear").
  std::string type = "brute_force";
  // FLANN's build parameters; `algorithm` is ignored (type decides). Defaults as
  // FlannKnnIndex::Options.
  FlannKnnIndex::Options flann;
  // FLANN's per-query parameters. Defaults as FlannKnnIndex::SearchParams.
  FlannKnnIndex::SearchParams search;

  bool IsValid(std::string* error) const;
};

// A new index of options.type over `vectors` (n x d, d >= 1; n may be 0). Throws
// std::invalid_argument for invalid options or vectors (as KnnIndex::Add).
std::unique_ptr<KnnIndex> BuildKnnIndex(const KnnVectors& vectors, const KnnIndexOptions& options);

// Why `index` (loaded from a file) cannot serve `vectors` with `options`, or "" if it
// can: another size or dim, other vectors (CRC-32 of the float32 bytes), another type,
// or other FLANN build parameters.
std::string WhyKnnIndexIsStale(const KnnIndex& index, const KnnVectors& vectors,
                               const KnnIndexOptions& options);

// What LoadOrBuildKnnIndex did.
struct KnnIndexCacheSummary {
  std::string path;
  bool rebuilt = false;      // false: the file was current and was loaded
  std::string why_rebuilt;   // "it does not exist", "it cannot be read (...)", or a
                             // WhyKnnIndexIsStale reason; "" when loaded
  std::string save_error;    // rebuilt but not saved (e.g. a read-only folder); "" = saved
};

// The index of `vectors` kept in the file `path`: loaded when the file holds exactly
// these vectors and was built with these options (the search parameters of a loaded
// FLANN index are then set to options.search); otherwise (missing, stale, corrupt or
// other parameters) built and saved atomically (KnnIndex::Save), so a crash never
// leaves a half-written index. A failed save does not fail the call: the index is
// returned unsaved and summary->save_error says why. summary may be null. Throws as
// BuildKnnIndex.
std::unique_ptr<KnnIndex> LoadOrBuildKnnIndex(const std::string& path, const KnnVectors& vectors,
                                              const KnnIndexOptions& options,
                                              KnnIndexCacheSummary* summary);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_KNN_KNN_INDEX_H_
