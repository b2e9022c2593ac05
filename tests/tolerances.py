"""Every numerical tolerance the tests use, in one place."""

#: exact kinematics from exact positions (float64 round-off)
EXACT = 1e-10
#: klt on the synthetic equibiaxial video: mean and RMSE of nodal Exx, Eyy errors (E = 0.625)
KLT_EQUIBIAXIAL_STRAIN = 0.01
#: klt on the quick (400 px) paper cases: final tracking RMSE in pixels
KLT_QUICK_TRACK_RMSE_PX = 0.5
#: rigid translation video: largest nodal strain magnitude measured by klt
KLT_RIGID_STRAIN = 2e-3
#: speckle renderer against brute-force evaluation of the deformed pattern (gray levels)
RENDER_GRAY_LEVELS = 0.02
#: dic on the quick (400 px, 11 frames) paper cases: final tracking RMSE in pixels
DIC_QUICK_TRACK_RMSE_PX = 0.05
#: dic on the quick paper cases: nodal strain RMSE of every component
DIC_QUICK_STRAIN_RMSE = 0.001
#: cotracker3 adapter with the stand-in predictor: largest position error along the known path
#: in pixels (float32 coordinates through a crop and the 384 x 512 model resolution)
COTRACKER_STANDIN_PX = 1e-3

# --- mpm3d (synthetic MPM stacks; the bars are 5 %, 3 deg and one z-step) ---
#: fold wavelength and fold heights (median, max, per fold): relative error
MPM_FOLD_RELATIVE = 0.05
#: fold orientation (crest direction), degrees
MPM_ORIENTATION_DEG = 3.0
#: RMS surface error of the height map and of the isosurface, in z-steps
MPM_SURFACE_RMS_ZSTEPS = 1.0
#: phase-correlation shift between height maps, pixels
MPM_SHIFT_PX = 0.1

# --- stereo (rendered scenes; the bars: RMS <= 0.1 px, baseline within 0.5 %) ---
#: stereo calibration RMS reprojection error, px
STEREO_CALIB_RMS_PX = 0.1
#: relative baseline error of the calibration
STEREO_BASELINE_RELATIVE = 0.005
#: reprojection RMS of the reconstructed points, px
STEREO_REPROJ_RMS_PX = 0.1
#: 3D RMSE of the reconstructed sheet with the true cameras, mm (~0.006 % of the distance)
STEREO_POINT_RMSE_MM = 0.03
#: cross-view matching RMSE, px
STEREO_MATCH_PX = 0.05

# --- surface_strain on curved surfaces (coordinates of order 1) ---
#: exact kinematics of exact positions: float64 round-off
ROUNDOFF = 1e-12
#: membrane strain RMSE of reconstruct --strain against the analytic field (the issue's bar)
STEREO_STRAIN_RMSE = 0.005
#: synthetic specimens: central differences of the analytic gradient (step 1e-4 px)
SPECIMEN_FINITE_DIFFERENCE = 1e-7
#: synthetic specimens: shift between frame 0 and a later frame pulled back by the true map, px
SPECIMEN_PULLBACK_SHIFT_PX = 0.05
#: synthetic specimens: OpenCV's pyramidal Lucas-Kanade from one frame's true points to the
#: next frame, px (median over 25 points; the motions are 3 to 5 px)
SPECIMEN_LK_TRACK_PX = 0.5
#: study of tracked synthetic specimens (klt, 192 px): specimen mean Exx, Eyy at the endpoint
STUDY_TRACKED_MEAN_STRAIN = 0.003
#: study of analytic fields with 0.05 px noise and a smooth bump: specimen mean Exx, Eyy
STUDY_FIELD_MEAN_STRAIN = 0.004
