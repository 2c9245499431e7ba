/**
 * @file bigusSliceFrame.h
 * @brief The orthonormal probe frame of one tracked ultrasound slice (DESIGN section 3).
 *
 * ImageToReference (row-major 4x4) maps a pixel index (column i, row j, 0, 1) to millimetres in the
 * reference frame; pixel (i, j) is the centre of the pixel. The slice frame is
 *   u = first column / |first column|, v = second column / |second column|, n = u x v,
 *   origin = fourth column (mm), spacing = (|first column|, |second column|) mm per pixel,
 * so that pixel (i, j) sits at origin + i * spacing[0] * u + j * spacing[1] * v.
 *
 * Plain C++ with no VTK types so that every backend (and the metafile reader) shares one definition.
 */
#ifndef bigusSliceFrame_h
#define bigusSliceFrame_h

#include "bigusGaussianMath.h"

#include <cmath>
#include <cstring>

namespace bigus
{

/// Result of checking an ImageToReference matrix.
enum class PoseStatus
{
  Ok = 0,
  NotFinite, ///< a NaN or Inf entry
  NotAffine, ///< the bottom row is not (0, 0, 0, 1)
  Singular,  ///< an image axis has (almost) zero length or the two axes are parallel
  Sheared    ///< the image axes are further from perpendicular than the tolerance
};

inline const char* PoseStatusText(PoseStatus s)
{
  switch (s)
  {
    case PoseStatus::Ok:
      return "ok";
    case PoseStatus::NotFinite:
      return "contains NaN or Inf";
    case PoseStatus::NotAffine:
      return "bottom row is not 0 0 0 1";
    case PoseStatus::Singular:
      return "is singular (an image axis has zero length or the axes are parallel)";
    case PoseStatus::Sheared:
      return "is sheared (image axes not perpendicular)";
  }
  return "unknown";
}

/// Orthonormal frame of a slice. All lengths in mm.
struct SliceFrame
{
  double u[3];         ///< unit image x axis (columns), reference frame
  double v[3];         ///< unit image y axis (rows), reference frame
  double n[3];         ///< unit slice normal u x v (elevation direction)
  double origin[3];    ///< centre of pixel (0, 0), mm
  double spacing[2];   ///< mm per pixel along u and v
  double shearDegrees; ///< |90 - angle between the two image axes|, degrees
};

/**
 * Build the slice frame of a row-major ImageToReference matrix and check it.
 * @param m                 16 doubles, row-major, pixel index -> mm.
 * @param maxShearDegrees   largest accepted |90 deg - angle(u, v)|; real calibrations carry a few
 *                          degrees of shear (the PLUS spine-phantom calibration has about 2.8).
 * @return PoseStatus::Ok, or the first problem found; @p frame is filled as far as it could be.
 */
inline PoseStatus ComputeSliceFrame(const double m[16], double maxShearDegrees, SliceFrame& frame)
{
  for (int k = 0; k < 16; ++k)
  {
    if (!std::isfinite(m[k]))
    {
      return PoseStatus::NotFinite;
    }
  }
  if (m[12] != 0.0 || m[13] != 0.0 || m[14] != 0.0 || std::abs(m[15] - 1.0) > 1e-12)
  {
    return PoseStatus::NotAffine;
  }
  double a[3] = { m[0], m[4], m[8] };
  double b[3] = { m[1], m[5], m[9] };
  const double na = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  const double nb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
  frame.origin[0] = m[3];
  frame.origin[1] = m[7];
  frame.origin[2] = m[11];
  frame.spacing[0] = na;
  frame.spacing[1] = nb;
  // Pixel spacings of real probes lie between micrometres and a few millimetres.
  const double tiny = 1e-9;
  if (na < tiny || nb < tiny)
  {
    return PoseStatus::Singular;
  }
  for (int k = 0; k < 3; ++k)
  {
    frame.u[k] = a[k] / na;
    frame.v[k] = b[k] / nb;
  }
  frame.n[0] = frame.u[1] * frame.v[2] - frame.u[2] * frame.v[1];
  frame.n[1] = frame.u[2] * frame.v[0] - frame.u[0] * frame.v[2];
  frame.n[2] = frame.u[0] * frame.v[1] - frame.u[1] * frame.v[0];
  const double nn = std::sqrt(frame.n[0] * frame.n[0] + frame.n[1] * frame.n[1] + frame.n[2] * frame.n[2]);
  const double cosine = frame.u[0] * frame.v[0] + frame.u[1] * frame.v[1] + frame.u[2] * frame.v[2];
  frame.shearDegrees = std::abs(std::asin(std::fmax(-1.0, std::fmin(1.0, cosine)))) * 180.0 / M_PI;
  if (nn < 1e-6)
  {
    return PoseStatus::Singular;
  }
  for (int k = 0; k < 3; ++k)
  {
    frame.n[k] /= nn;
  }
  return frame.shearDegrees > maxShearDegrees ? PoseStatus::Sheared : PoseStatus::Ok;
}

/// The centre pixel ((width - 1) / 2, (height - 1) / 2) of a slice in its plane coordinates (mm, elevation
/// 0): the pivot of a pose correction (CorrectPose, FieldGradients::SlicePoses).
inline void SliceCentre(const double pixelToPlane[3], int width, int height, double centre[3])
{
  const double i = 0.5 * (width - 1), j = 0.5 * (height - 1);
  centre[0] = i * pixelToPlane[0] + j * pixelToPlane[1];
  centre[1] = j * pixelToPlane[2];
  centre[2] = 0;
}

/**
 * The in-plane covariance (xx, xy, yy; mm^2, rendering axes u, v_perp) of a Gaussian low-pass of @p variance
 * pixels^2 along each pixel axis of a slice whose pixel (i, j) lies at (i P0 + j P1, j P2) (ComputeRenderingFrame's
 * @p pixelToPlane): variance (a a^T + b b^T) for the pixel's edges a = (P0, 0) and b = (P1, P2), so that a
 * box of w x w pixels, sheared or not, has the covariance of variance w^2 / 12.
 */
inline void PixelLowPassCovariance(const double pixelToPlane[3], double variance, double lowPass[3])
{
  lowPass[0] = variance * (pixelToPlane[0] * pixelToPlane[0] + pixelToPlane[1] * pixelToPlane[1]);
  lowPass[1] = variance * pixelToPlane[1] * pixelToPlane[2];
  lowPass[2] = variance * pixelToPlane[2] * pixelToPlane[2];
}

/**
 * Orthonormal rendering frame of a slice and the affine map from pixel index to in-plane position.
 * Rows of @p F: u, v_perp (v made orthogonal to u), n = u x v. Pixel (i, j) lies at in-plane position
 * x = i * pixelToPlane[0] + j * pixelToPlane[1], y = j * pixelToPlane[2] (mm), elevation 0; this is
 * exact for a sheared pose too (pixelToPlane[1] = s_v cos(angle(u, v)) is then non-zero).
 */
inline PoseStatus ComputeRenderingFrame(
  const double m[16], double maxShearDegrees, double F[3][3], double origin[3], double pixelToPlane[3])
{
  SliceFrame frame;
  const PoseStatus status = ComputeSliceFrame(m, maxShearDegrees, frame);
  if (status != PoseStatus::Ok)
  {
    return status;
  }
  const double c = frame.u[0] * frame.v[0] + frame.u[1] * frame.v[1] + frame.u[2] * frame.v[2];
  double vp[3] = { frame.v[0] - c * frame.u[0], frame.v[1] - c * frame.u[1], frame.v[2] - c * frame.u[2] };
  const double nv = std::sqrt(vp[0] * vp[0] + vp[1] * vp[1] + vp[2] * vp[2]);
  for (int k = 0; k < 3; ++k)
  {
    F[0][k] = frame.u[k];
    F[1][k] = vp[k] / nv;
    F[2][k] = frame.n[k];
    origin[k] = frame.origin[k];
  }
  pixelToPlane[0] = frame.spacing[0];
  pixelToPlane[1] = frame.spacing[1] * c;
  pixelToPlane[2] = frame.spacing[1] * nv;
  return PoseStatus::Ok;
}

/**
 * The pose @p m (row-major ImageToReference of a @p width x @p height slice) moved by the rigid correction
 * @p xi: rotation vector xi[0..2] (rad) about the slice's centre pixel ((width - 1) / 2, (height - 1) / 2)
 * and translation xi[3..5] (mm), both in the slice's rendering axes (ComputeRenderingFrame's u, v_perp, n),
 * as bigus::CorrectSliceFrame moves its frame; the gradient FieldGradients::SlicePoses is taken with
 * respect to this xi. @p corrected = C m with C the rigid motion of the reference frame that moves the slice
 * (pixel spacing and shear are kept). Returns the status of @p m (@p corrected untouched unless Ok).
 */
inline PoseStatus CorrectPose(const double m[16], int width, int height, const double xi[6], double corrected[16])
{
  SliceFrameD frame, moved;
  double pixelToPlane[3];
  const PoseStatus status = ComputeRenderingFrame(m, 90, frame.F, frame.Origin, pixelToPlane);
  if (status != PoseStatus::Ok)
  {
    return status;
  }
  double pivot[3];
  SliceCentre(pixelToPlane, width, height, pivot);
  CorrectSliceFrame(frame, pivot, xi, moved);
  // C x = Q x + d with Q = F'^T F and d = o' - Q o.
  double Q[3][3], d[3];
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      Q[i][j] = moved.F[0][i] * frame.F[0][j] + moved.F[1][i] * frame.F[1][j] + moved.F[2][i] * frame.F[2][j];
    }
  }
  for (int i = 0; i < 3; ++i)
  {
    d[i] = moved.Origin[i] - (Q[i][0] * frame.Origin[0] + Q[i][1] * frame.Origin[1] + Q[i][2] * frame.Origin[2]);
  }
  double out[16];
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 4; ++j)
    {
      out[4 * i + j] = Q[i][0] * m[j] + Q[i][1] * m[4 + j] + Q[i][2] * m[8 + j] + (j == 3 ? d[i] : 0.0);
    }
  }
  for (int j = 0; j < 4; ++j)
  {
    out[12 + j] = m[12 + j];
  }
  std::memcpy(corrected, out, sizeof(out));
  return PoseStatus::Ok;
}

} // namespace bigus

#endif
