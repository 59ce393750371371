// Tracking a recorded image sequence from disk, and the pose CSV it produces.
//
// Folder layout (what `mcms render` writes, and what a user's recording must follow):
//   images/<camera name>/<frame>.png   one folder per rig camera, named as in the rig
//                                      file; file stems are frame numbers (any digits);
//                                      also .pgm, .tif/.tiff (`mcms render --format`),
//                                      .jpg, .bmp: read by vision/image_file.h
//   frames.csv (optional)              frame,time_s  -- otherwise time = frame / rate;
//                                      cameras not triggered together may add a column
//                                      time_s_<camera name> per camera: its exposure
//                                      times (an empty cell: the frame's time_s), which
//                                      the camera audit predicts its images at
#pragma once

#include <array>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/interrupt.h"
#include "tracking/tracker.h"
#include "vision/image_file.h"

namespace mcms {

struct SequenceInput {
  std::filesystem::path images_dir;  // holds one folder per camera
  std::filesystem::path frames_csv;  // optional
  double frame_rate_hz = 10.0;       // used when there is no frames.csv
};

struct ImageSequence {
  std::vector<size_t> frames;   // sorted frame numbers
  std::vector<double> times_s;  // one per frame
  // [frame * cameras() + camera]: the camera's exposure time (frames.csv's time_s_<camera>;
  // NaN: the frame's time); empty when frames.csv gives none.
  std::vector<double> camera_times_s;
  // Where frame i's image of camera c is: ImagePath(i, c), an empty path when it is
  // missing. Stored compactly (one folder per camera, one name per image): a listing of
  // 100,000 frame sets of 4 cameras takes about 13 MB, where a std::filesystem::path per
  // image took 280 MB.
  std::vector<std::filesystem::path> camera_dirs;  // [camera]
  // [frame * cameras() + camera]: a file name inside camera_dirs[camera], or a whole path
  // (SetImagePath), or "" when the image is missing.
  std::vector<std::string> image_names;
  // [camera] {width, height} the rig gives; an image of another size (read from a PNG's
  // header before decoding, from the decoded image otherwise) degrades its frame.
  // Empty: not checked.
  std::vector<std::array<int, 2>> image_sizes;

  size_t cameras() const { return camera_dirs.size(); }
  std::filesystem::path ImagePath(size_t i, size_t c) const;
  // Frame i's image of camera c is the file `path` (any folder; empty = missing).
  void SetImagePath(size_t i, size_t c, const std::filesystem::path& path);
};

// Lists the frames and checks the layout against the rig: InputError when the folder
// is missing or empty, a rig camera has no folder, there are folders for cameras the
// rig does not have, or the first image of a camera has another size than the rig says.
ImageSequence ScanImageSequence(const SequenceInput& input, const CameraRig& rig);

// The images of frame index i (seq.frames[i]), one per camera, read by ReadImageFile
// (vision/image_file.h: our PNG decoder, PGM/TIFF memory-mapped, OpenCV for the rest); a
// missing or undecodable image (a wrong CRC, a truncated file, a zlib bomb), or one of
// another size than seq.image_sizes (a PNG whose header claims 60000 x 60000 is not
// decoded), is an empty Mat with the reason, naming the file, in problems[c].
std::vector<cv::Mat> LoadFrameImages(const ImageSequence& seq, size_t i, std::vector<std::string>* problems);

// LoadFrameImages in two steps (ImageFileRows): each file read, checked and (PNG)
// inflated, with the same problems; the rows of a PNG our decoder takes are unfiltered
// later, by Prepare(), as the detector needs them. A missing or refused image has an
// empty image().
std::vector<ImageFileRows> LoadFrameRows(const ImageSequence& seq, size_t i, std::vector<std::string>* problems);

// The most frames TrackImageSequenceStreaming holds at once (read and detected but not
// yet handed to on_frame) on `threads` threads: its reorder window, 4 per thread.
size_t SequenceWindow(int threads);

// Where TrackFramesStreaming gets its frames from: `count` frame sets, index i has the
// frame number frame(i), the time time_s(i) and the images images(i, problems) (one per
// rig camera: an empty Mat when missing, with the reason in (*problems)[c]). images is
// called from several threads at once and must be thread-safe.
struct FrameSource {
  size_t count = 0;
  std::function<size_t(size_t)> frame;
  std::function<double(size_t)> time_s;
  // Optional: each camera's exposure time in frame i (FrameResult::camera_time_s).
  std::function<std::vector<double>(size_t)> camera_time_s;
  std::function<std::vector<cv::Mat>(size_t, std::vector<std::string>*)> images;
  // Optional: the images read in part (LoadFrameRows), one per rig camera, thread-safe as
  // `images`. With a tracker whose options have predicted_windows, TrackFramesStreaming
  // takes these instead, and only the rows the detector reads are unfiltered (the rows of
  // the windows and of its sample; every row where it detects the whole image).
  std::function<std::vector<ImageFileRows>(size_t, std::vector<std::string>*)> image_rows;
};

// A FrameSource reading the image files of `seq` (LoadFrameImages, and LoadFrameRows for
// predicted windows); seq must outlive it.
FrameSource FilesOf(const ImageSequence& seq);

// Runs the tracker over every frame of `source`: the images are fetched and their blobs
// detected on `threads` threads, at most SequenceWindow(threads) frames ahead of the frame
// being delivered, and the frames are processed (matching, identification, pose) in order
// in the calling thread, so the results do not depend on `threads`. Each frame's result
// goes to on_frame as soon as it is finished, in frame order. progress(done, total) is
// called after each frame. An exception from fetching, detection or on_frame stops every
// thread and is rethrown. Returns the greatest number of frames held at once.
size_t TrackFramesStreaming(const FrameSource& source, Tracker& tracker,
                            const std::function<void(FrameResult&&)>& on_frame,
                            const std::function<void(size_t, size_t)>& progress = {}, int threads = 1);

// Runs the tracker over every frame (missing or undecodable images become per-frame
// problems) and hands each frame's result to on_frame as soon as it is finished, in frame
// order; nothing of a frame is kept after on_frame returns, so memory does not grow with
// the length of the sequence. Images are read and their blobs detected on `threads`
// threads, at most SequenceWindow(threads) frames ahead of the frame being delivered; the
// frames are processed in order, so the results do not depend on `threads`.
// progress(done, total) is called after each frame. An exception from reading, detection
// or on_frame stops every thread and is rethrown. Returns the greatest number of frames
// that were held at once (at most SequenceWindow(threads)).
size_t TrackImageSequenceStreaming(const ImageSequence& seq, Tracker& tracker,
                                   const std::function<void(FrameResult&&)>& on_frame,
                                   const std::function<void(size_t, size_t)>& progress = {}, int threads = 1);

// The same, keeping every result (memory grows with the sequence: for short sequences
// and callers that need them all; `mcms track` streams).
std::vector<FrameResult> TrackImageSequence(const ImageSequence& seq, Tracker& tracker,
                                            const std::function<void(size_t, size_t)>& progress = {},
                                            int threads = 1);

// The pose CSV: one row per frame: frame,time_s,status,reason,x_m,y_m,z_m,qw,qx,qy,qz,
// diagnostics, then the 36 entries of the 6x6 covariance in the [dtheta; dp] layout, named
// cov_<row>_<col> with rows/cols rx,ry,rz (rad) and px,py,pz (m): units rad^2, rad*m, m^2,
// then the caller's extra columns (e.g. the errors against a truth file). Pose cells are
// empty for lost frames, and so is an extra value that is NaN.
//
// Written as the frames stream past: each Add() appends a row to a temporary file beside
// `path`; Finish(comments) writes `path` atomically (each comment line first as a line
// starting with "# ": the noise model the covariances assume and summaries only known at
// the end; the project's CSV readers skip such lines), then the header and the rows.
// Destroyed without Finish() (an error mid-run), it removes its temporary file and leaves
// no `path`.
class PoseCsvWriter {
 public:
  explicit PoseCsvWriter(std::filesystem::path path, std::vector<std::string> extra_columns = {});
  ~PoseCsvWriter();
  PoseCsvWriter(const PoseCsvWriter&) = delete;
  PoseCsvWriter& operator=(const PoseCsvWriter&) = delete;

  // `extra` holds one value per extra column.
  void Add(const FrameResult& f, const std::vector<double>& extra = {});
  void Finish(const std::vector<std::string>& comments = {});
  size_t rows() const { return rows_; }

 private:
  std::filesystem::path path_, rows_path_;
  std::unique_ptr<RemovedOnInterrupt> rows_guard_;  // the rows file goes if the run is interrupted
  std::vector<std::string> extra_columns_;
  std::unique_ptr<std::ofstream> rows_out_;
  size_t rows_ = 0;
  bool finished_ = false;
};

// All of `results` through a PoseCsvWriter.
void WritePoseCsv(const std::filesystem::path& path, const std::vector<FrameResult>& results,
                  const std::vector<std::string>& comments = {});

}  // namespace mcms
