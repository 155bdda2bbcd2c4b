// Copyright 2026 The tactfunc Authors.
//
// Frames of a video decoded on demand (private to estimation/data/dataset.cc). A video is
// read through once when it is opened -- to count its frames, check their size, keep a
// fingerprint of each and keep the reference frame -- and is then decoded again frame by
// frame as frames are asked for, so the memory it takes does not grow with its length:
// one decoder, a few cached 8-bit frames and 8 bytes per frame.
#ifndef TACTFUNC_ESTIMATION_DATA_INTERNAL_VIDEO_READER_H_
#define TACTFUNC_ESTIMATION_DATA_INTERNAL_VIDEO_READER_H_

#include <cstddef>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "estimation/data/codecs.h"
#include "models/core/image.h"

namespace tactfunc::internal {

class VideoReader;

// Bounds how many VideoReaders sharing it keep a decoder open at once: a set of many
// video clips holds one decoder per recently read clip, not one per clip.
class VideoDecoderBudget {
 public:
  explicit VideoDecoderBudget(std::size_t max_open) : max_open_(max_open < 1 ? 1 : max_open) {}
  // Marks `reader` as the most recently used. Returns the least recently used other
  // reader that should close its decoder to stay within the budget, or nullptr.
  VideoReader* Use(VideoReader* reader);
  // Forgets `reader` (it closed its decoder or is being destroyed).
  void Forget(VideoReader* reader);

 private:
  std::mutex mutex_;
  std::size_t max_open_;
  std::list<VideoReader*> open_;  // most recently used first
};

class VideoReader {
 public:
  struct Options {
    // Random access by seeking the decoder (CAP_PROP_POS_FRAMES). Every frame a seek
    // lands on is checked against the fingerprint taken when the video was opened;
    // a miss falls back to reading forward from the start. false: never seek (always
    // read forward, from the start when going back).
    bool seek = true;
    // Decoded 8-bit frames kept for reuse (threads asking for neighbouring frames out
    // of order are served from here instead of seeking back).
    std::size_t cache_frames = 8;
    // Shared by the readers of one dataset; nullptr = no bound.
    std::shared_ptr<VideoDecoderBudget> budget;
  };
  // What Frame() had to do, for tests and measurements.
  struct Stats {
    std::uint64_t cache_hits = 0;
    std::uint64_t frames_decoded = 0;  // frames read or skipped by the decoder
    std::uint64_t seeks = 0;
    std::uint64_t seek_misses = 0;     // seeks that landed on another frame or failed
    std::uint64_t rewinds = 0;         // reopened to read forward from the start
  };

  // The most frames a video may have (8 bytes of fingerprint each).
  static constexpr std::size_t kMaxFrames = 1000000;

  // Opens `path` and reads it through once. Keeps frame `reference_index` in
  // *reference (as ImageFromRgb8Mat gives it). Throws DatasetError naming the path
  // for a file OpenCV cannot open, a video without frames, frames of different
  // sizes, a frame larger than kMaxFramePixels, or a reference_index out of range.
  VideoReader(const std::string& path, std::size_t reference_index, Image* reference,
              Options options);
  ~VideoReader();
  VideoReader(const VideoReader&) = delete;
  VideoReader& operator=(const VideoReader&) = delete;

  const std::string& path() const { return path_; }
  std::size_t num_frames() const { return fingerprints_.size(); }
  int rows() const { return rows_; }
  int cols() const { return cols_; }

  // Frame `index` (0-based, counting every frame of the video), in R, G, B order as
  // ImageFromRgb8Mat gives it. Thread-safe. The pixels are always those seen when the
  // video was opened: a decoded frame whose fingerprint differs is an error (the file
  // changed). Throws std::out_of_range for a bad index and DatasetError.
  Image Frame(std::size_t index);
  // Releases the decoder and the cache; the next Frame() reopens the file.
  void Close();
  Stats stats() const;

 private:
  void OpenDecoderLocked();
  void CloseLocked();
  // The 8-bit frame `index`, decoded (or cached); the caller holds mutex_.
  cv::Mat DecodeLocked(std::size_t index);
  // Reads from next_ up to frame `index`; false if a frame read does not match its
  // fingerprint or the decoder ends early.
  bool ReadForwardLocked(std::size_t index, cv::Mat* frame);
  bool SeekLocked(std::size_t index, cv::Mat* frame);
  bool Matches(std::size_t index, const cv::Mat& frame) const;
  void CacheLocked(std::size_t index, const cv::Mat& frame);

  std::string path_;
  Options options_;
  int rows_ = 0;
  int cols_ = 0;
  int type_ = 0;
  std::vector<std::uint64_t> fingerprints_;  // one per frame, taken when opened

  mutable std::mutex mutex_;
  codecs::VideoCapture capture_;  // open while decoding; closed by Close() or the budget
  std::size_t next_ = 0;      // index of the frame the decoder reads next
  std::list<std::pair<std::size_t, cv::Mat>> cache_;  // most recent first
  Stats stats_;
};

// A fingerprint of an 8-bit frame's size, type and pixels.
std::uint64_t FrameFingerprint(const cv::Mat& frame);

}  // namespace tactfunc::internal

#endif  // TACTFUNC_ESTIMATION_DATA_INTERNAL_VIDEO_READER_H_
