# Runs the haptic segmentation example with and without guidance (lockstep)
# and checks its outcomes from summary.json:
#  - the guided run painted white matter: at least 1 mL, at least 95 % of it
#    inside the reference segmentation, no voxel outside the brain;
#  - the guidance force stayed within its 1.5 N clamp;
#  - guidance kept the probe in more homogeneous tissue than the control:
#    a lower mean edge strength and a larger adaptive radius along the path,
#    where it painted (measured: 0.049 and 4.89 mm guided, 0.134 and
#    4.50 mm without);
#  - the outputs exist.
# -DEXAMPLE=program -DOUT=dir
include(${CMAKE_CURRENT_LIST_DIR}/../common/run_example.cmake)
dm_run_example(NAME guided ARGS --duration 8 OUTPUTS segmentation.nii.gz forces.csv forces.png slice.png)
set(summary_guided "${summary}")
dm_run_example(NAME control ARGS --duration 8 --no-guidance OUTPUTS segmentation.nii.gz forces.csv forces.png slice.png)
set(summary_control "${summary}")
string(JSON ml GET "${summary_guided}" painted_ml)
string(JSON precision GET "${summary_guided}" precision)
string(JSON outside GET "${summary_guided}" outside_brain_voxels)
string(JSON force GET "${summary_guided}" max_force_N)
string(JSON edgeGuided GET "${summary_guided}" mean_edge_strength)
string(JSON edgeControl GET "${summary_control}" mean_edge_strength)
string(JSON forceControl GET "${summary_control}" max_force_N)
string(JSON radiusGuided GET "${summary_guided}" mean_radius_mm)
string(JSON radiusControl GET "${summary_control}" mean_radius_mm)
if(ml LESS 1.0)
  message(FATAL_ERROR "painted only ${ml} mL")
endif()
if(precision LESS 0.95)
  message(FATAL_ERROR "precision ${precision} against the reference white matter, expected >= 0.95")
endif()
if(NOT outside EQUAL 0)
  message(FATAL_ERROR "${outside} voxels painted outside the brain")
endif()
if(force GREATER 1.5000001 OR force LESS 0.05)
  message(FATAL_ERROR "guidance force peaked at ${force} N, expected a felt force within the 1.5 N clamp")
endif()
if(NOT forceControl EQUAL 0)
  message(FATAL_ERROR "the control run rendered ${forceControl} N")
endif()
if(NOT edgeGuided LESS edgeControl)
  message(FATAL_ERROR "mean edge strength along the path ${edgeGuided} with guidance, ${edgeControl} without")
endif()
if(NOT radiusGuided GREATER radiusControl)
  message(FATAL_ERROR "mean adaptive radius along the path ${radiusGuided} mm with guidance, ${radiusControl} mm without")
endif()
message(STATUS "ok: ${ml} mL painted, precision ${precision}, edge strength ${edgeGuided} guided vs ${edgeControl}")
