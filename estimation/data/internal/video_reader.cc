// Copyright 2026 The tactfunc Authors.
#include "estimation/data/internal/video_reader.h"

#include <algorithm>
#include <functional>
#include <stdexcept>
#include <string_view>
#include <utility>

#include "estimation/data/image_io.h"
#include "estimation/data/internal/opencv_image.h"

namespace tactfunc::internal {
namespace {

// Frames ahead of the decoder that are reached by reading on rather than by seeking.
constexpr std::size_t kMaxForwardGap = 32;

std::string FrameName(const std::string& path, std::size_t index) {
  return path + "#" + std::to_string(index);
}

std::string MatShapeText(const cv::Mat& mat) {
  return std::to_string(mat.rows) + "x" + std::to_string(mat.cols) + "x" +
         std::to_string(mat.channels());
}

void OpenCapture(const std::string& path, codecs::VideoCapture* capture) {
  std::string reason;
  if (!capture->open(path, &reason) && !reason.empty()) {
    throw DatasetError(path + ": expected a video OpenCV can open, got an error: " + reason);
  }
  if (!capture->isOpened()) {
    throw DatasetError(path +
                       ": expected a video OpenCV can open (AVI/MP4/MKV/MOV with a codec this "
                       "OpenCV build decodes), got one it cannot open");
  }
}

}  // namespace

std::uint64_t FrameFingerprint(const cv::Mat& frame) {
  const cv::Mat continuous = frame.isContinuous() ? frame : frame.clone();
  const std::string_view bytes(reinterpret_cast<const char*>(continuous.data),
                               continuous.total() * continuous.elemSize());
  std::uint64_t h = std::hash<std::string_view>()(bytes);
  for (const std::uint64_t v : {std::uint64_t(frame.rows), std::uint64_t(frame.cols),
                                std::uint64_t(frame.type())}) {
    h ^= v + 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2);
  }
  return h;
}

// ---------------------------------------------------------------------------------
// VideoDecoderBudget.

VideoReader* VideoDecoderBudget::Use(VideoReader* reader) {
  std::lock_guard<std::mutex> lock(mutex_);
  open_.remove(reader);
  open_.push_front(reader);
  if (open_.size() <= max_open_) return nullptr;
  VideoReader* evicted = open_.back();
  open_.pop_back();
  return evicted;
}

void VideoDecoderBudget::Forget(VideoReader* reader) {
  std::lock_guard<std::mutex> lock(mutex_);
  open_.remove(reader);
}

// ---------------------------------------------------------------------------------
// VideoReader.

VideoReader::VideoReader(const std::string& path, std::size_t reference_index, Image* reference,
                         Options options)
    : path_(path), options_(std::move(options)) {
  codecs::VideoCapture capture;
  OpenCapture(path_, &capture);
  cv::Mat frame;
  cv::Mat first;
  while (capture.read(&frame)) {
    const std::size_t index = fingerprints_.size();
    if (index == 0) {
      if (static_cast<std::int64_t>(frame.rows) * frame.cols > kMaxFramePixels) {
        throw DatasetError(FrameName(path_, 0) + ": expected a frame of at most " +
                           std::to_string(kMaxFramePixels) + " pixels, got " +
                           std::to_string(frame.rows) + "x" + std::to_string(frame.cols));
      }
      first = frame.clone();
      rows_ = frame.rows;
      cols_ = frame.cols;
      type_ = frame.type();
    } else if (frame.rows != rows_ || frame.cols != cols_ || frame.type() != type_) {
      throw DatasetError(FrameName(path_, index) + ": expected " + MatShapeText(first) +
                         " like frame 0, got " + MatShapeText(frame));
    }
    if (index >= kMaxFrames) {
      throw DatasetError(path_ + ": expected a video of at most " + std::to_string(kMaxFrames) +
                         " frames, got more");
    }
    fingerprints_.push_back(FrameFingerprint(frame));
    if (index == reference_index) *reference = ImageFromRgb8Mat(frame, FrameName(path_, index));
  }
  if (fingerprints_.empty()) {
    throw DatasetError(path_ + ": expected at least one decodable frame, got none");
  }
  if (reference_index >= fingerprints_.size()) {
    throw DatasetError(path_ + ": OpenOptions::reference_index: expected a frame index < " +
                       std::to_string(fingerprints_.size()) + " (the number of frames), got " +
                       std::to_string(reference_index));
  }
}

VideoReader::~VideoReader() {
  if (options_.budget) options_.budget->Forget(this);
}

Image VideoReader::Frame(std::size_t index) {
  if (index >= fingerprints_.size()) {
    throw std::out_of_range("VideoReader::Frame: index " + std::to_string(index) +
                            " >= number of frames " + std::to_string(fingerprints_.size()));
  }
  // The budget is asked before this reader's lock is taken, and the evicted reader is
  // closed without holding the budget's: no two locks are ever held together.
  if (options_.budget) {
    if (VideoReader* evicted = options_.budget->Use(this)) evicted->Close();
  }
  cv::Mat frame;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    frame = DecodeLocked(index);  // shares the cached pixels; they are never written
  }
  return ImageFromRgb8Mat(frame, FrameName(path_, index));
}

void VideoReader::Close() {
  std::lock_guard<std::mutex> lock(mutex_);
  CloseLocked();
}

VideoReader::Stats VideoReader::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

void VideoReader::OpenDecoderLocked() {
  capture_.release();
  OpenCapture(path_, &capture_);
  next_ = 0;
}

void VideoReader::CloseLocked() {
  capture_.release();
  cache_.clear();
  next_ = 0;
}

cv::Mat VideoReader::DecodeLocked(std::size_t index) {
  for (auto it = cache_.begin(); it != cache_.end(); ++it) {
    if (it->first != index) continue;
    ++stats_.cache_hits;
    cache_.splice(cache_.begin(), cache_, it);
    return cache_.front().second;
  }
  cv::Mat frame;
  if (!capture_.isOpened()) OpenDecoderLocked();
  if (index >= next_ && index - next_ <= kMaxForwardGap) {
    if (ReadForwardLocked(index, &frame)) return frame;
  } else if (options_.seek) {
    if (SeekLocked(index, &frame)) return frame;
  }
  // Back to the start and read forward: slow, but lands on the right frame whatever
  // the container's index says.
  ++stats_.rewinds;
  OpenDecoderLocked();
  if (ReadForwardLocked(index, &frame)) return frame;
  CloseLocked();
  throw DatasetError(FrameName(path_, index) +
                     ": expected the frame seen when the video was opened, got " +
                     (frame.empty() ? std::string("the end of the video before it")
                                    : "other pixels") +
                     " (was the file changed?)");
}

bool VideoReader::ReadForwardLocked(std::size_t index, cv::Mat* frame) {
  while (next_ <= index) {
    const std::size_t current = next_;
    // Frames near the target are kept (neighbours asked for out of order by other
    // threads); those further back are only stepped over.
    const bool keep = index - current < options_.cache_frames || current == index;
    cv::Mat decoded;  // a fresh buffer each time: cached frames are never overwritten
    const bool ok = keep ? capture_.read(&decoded) : capture_.grab();
    ++stats_.frames_decoded;
    if (!ok) {
      frame->release();
      next_ = fingerprints_.size();  // unknown: the next request starts over
      return false;
    }
    ++next_;
    if (!keep) continue;
    *frame = decoded;
    if (!Matches(current, decoded)) {
      next_ = fingerprints_.size();
      return false;
    }
    CacheLocked(current, decoded);
  }
  return true;
}

bool VideoReader::SeekLocked(std::size_t index, cv::Mat* frame) {
  ++stats_.seeks;
  bool ok = capture_.seek(index);
  cv::Mat decoded;
  ok = ok && capture_.read(&decoded);
  *frame = decoded;
  ++stats_.frames_decoded;
  // The fingerprint decides whether the seek landed where asked: containers whose
  // index is coarse or missing land elsewhere.
  if (!ok || !Matches(index, *frame)) {
    ++stats_.seek_misses;
    next_ = fingerprints_.size();
    return false;
  }
  next_ = index + 1;
  CacheLocked(index, *frame);
  return true;
}

bool VideoReader::Matches(std::size_t index, const cv::Mat& frame) const {
  return frame.rows == rows_ && frame.cols == cols_ && frame.type() == type_ &&
         FrameFingerprint(frame) == fingerprints_[index];
}

void VideoReader::CacheLocked(std::size_t index, const cv::Mat& frame) {
  if (options_.cache_frames == 0) return;
  cache_.emplace_front(index, frame);
  while (cache_.size() > options_.cache_frames) cache_.pop_back();
}

}  // namespace tactfunc::internal
