# Runs the osteotomy example (lockstep) twice and checks from summary.json:
#  - the skull region and both fragments are substantial (> 2000 voxels each);
#  - the hand going exactly to the anatomical pose puts the fragment back
#    within 0.3 mm RMS at its reference points (from > 5 mm), with the 1 mm
#    saw kerf open (no voxel pair presses the other fragment) and no force
#    left on the hand;
#  - the hand pressing 2 mm past it, into the fixed fragment: the fragment
#    closes the 1 mm saw kerf and stops there (final error < 1.5 mm, contact
#    depth below one voxel), and the hand feels the coupling pull it back
#    out along the cut normal (> 0.2 N, equal to k_c times the offset within
#    1 %);
#  - the outputs exist.
# -DEXAMPLE=program -DOUT=dir
include(${CMAKE_CURRENT_LIST_DIR}/../common/run_example.cmake)

macro(get key)
  string(JSON ${key} GET "${summary}" ${key})
endmacro()

dm_run_example(NAME home ARGS --push 0 OUTPUTS fragments.nii.gz hand.dmrec forces.csv forces.png alignment.csv hand.csv)
get(fixed_voxels)
get(moving_voxels)
get(initial_error_m)
get(final_error_m)
get(final_contacts)
get(max_force_N)
get(rest_force_along_normal_N)
if(fixed_voxels LESS 2000 OR moving_voxels LESS 2000)
  message(FATAL_ERROR "fragments of ${fixed_voxels} and ${moving_voxels} voxels")
endif()
if(initial_error_m LESS 0.005 OR final_error_m GREATER 0.0003)
  message(FATAL_ERROR "home: error ${initial_error_m} m -> ${final_error_m} m, expected > 5 mm -> < 0.3 mm")
endif()
if(NOT final_contacts EQUAL 0)
  message(FATAL_ERROR "home: ${final_contacts} voxel pairs press across the open kerf at the anatomical pose")
endif()
if(rest_force_along_normal_N GREATER 0.02 OR rest_force_along_normal_N LESS -0.02)
  message(FATAL_ERROR "home: ${rest_force_along_normal_N} N left on the hand at rest")
endif()

dm_run_example(NAME pressed ARGS --push 2)
get(final_error_m)
get(final_contacts)
if(final_contacts LESS 1)
  message(FATAL_ERROR "pressed: no voxel pair holds the fragment at the cut")
endif()
get(max_contact_depth_m)
get(rest_force_along_normal_N)
get(rest_force_minus_coupling_N)
if(final_error_m GREATER 0.0015)
  message(FATAL_ERROR "pressed: the fragment ended ${final_error_m} m from home (the kerf is 1 mm)")
endif()
if(max_contact_depth_m GREATER 0.001)
  message(FATAL_ERROR "pressed: leaf spheres overlapped ${max_contact_depth_m} m: the fragment sank in")
endif()
if(rest_force_along_normal_N LESS 0.2)
  message(FATAL_ERROR "pressed: the hand feels ${rest_force_along_normal_N} N back along the cut normal")
endif()
if(rest_force_minus_coupling_N GREATER 0.0035)
  message(FATAL_ERROR "pressed: rest force and coupling k_c times offset differ by ${rest_force_minus_coupling_N} N")
endif()
message(STATUS "ok")
