"""The virtual lab's second string physics (``lab.physics: elastica``): a PyElastica Cosserat rod.

Independent of the MuJoCo chain (:mod:`stringcast_lab.physics`, :mod:`stringcast_lab.air`) and of
the pipeline's string model (:mod:`stringcast.model`): from the lab it takes only what the string
*is* (:class:`~stringcast_lab.mjcf.StringPhysics`, plain data), the arm's servo and hand path
(:mod:`stringcast_lab.servo`) and the :class:`~stringcast_lab.recording.Recording` it returns.
docs/lab_physics.md has the same account with the figures measured.

The rod (PyElastica 1.0, ``CosseratRod``; Gazzola, Dudte & Mahadevan 2018, R. Soc. open sci. 5:
171628): ``phys.n_links`` = ``lab.links_per_point`` x n_points equal elements (10-11 mm for the
project's strings) in the vertical x-y plane, gravity 9.81 m/s^2 along -y, position Verlet.
Its nodes are the Recording's sites (node k at rest arc k L / n, node 0 the grasp).

* Stretch, shear, bending and twist are the rod's own (PyElastica's discrete Cosserat
  operators; twist is never excited in the plane). Per element: EA, alpha G A, EI, G J
  (:mod:`.material`); at a junction the two half elements' EI act in series.
* Internal damping (:class:`~.plugins.CordDamping`): Kelvin-Voigt dashpots, the couple
  eta d(kappa)/dt with eta = the configured ``bending_damping`` (N m^2 s; the MuJoCo chain's
  hinges get eta / l_link, the same continuum value) and an axial eta_a d(eps)/dt with loss
  factor 0.03 at the first axial mode. Applied as the exact backward-Euler step of the
  dashpots after each step (a tridiagonal solve), so they never limit the step and never touch
  a rigid motion. PyElastica's ``AnalyticalLinearDamper`` was not used: it damps absolute
  velocities, a drag on the whole swing (it would shift the pendulum period and the cast);
  nor the ``LaplaceDissipationFilter``: it removes a share of the grid-scale velocities per
  step, so its physical strength depends on dt, and it has no material value to map.
* Air (:class:`~.plugins.AirDrag`, own code): per element, normal drag
  0.5 rho C_n d l |v_n| v_n with Sucker & Brauer's cylinder correlation (1975, Wärme- und
  Stoffübertragung 8: 149-158) and skin friction 0.5 rho C_f pi d l |v_t| v_t with the laminar
  (Blasius) C_f = 1.328 / sqrt(Re_L) over the string's length (Schlichting & Gersten,
  Boundary-Layer Theory; a lower bound on a thin cylinder, Glauert & Lighthill 1955, and 1 % of
  the normal drag); per clay lump, sphere drag with Morrison's correlation (An Introduction to
  Fluid Mechanics, CUP 2013). Still air; the MuJoCo lab's White and Clift-Gauvin fits are not
  used (nor its code).
* Clay weights: point masses on the two nearest nodes by the lever rule (centre of mass kept),
  their own 2/5 m r^2 on the neighbouring elements, their sphere drag at the interpolated
  velocity.
* Stiff sections: an LDPE tube (E 0.25 GPa, rho 920 kg/m^3, nu 0.45) of the configured outer
  diameter whose wall the configured g/m gives (8 mm, 40 g/m: 2.9 mm bore, EI 0.049 N m^2,
  1600-2500 x the cord's) adds its EA, EI, G J and thin-tube shear to every element it covers more
  than half of, and its mass to every element it touches. The explicit step resolves it (its
  modes are within 1.25 x the cord's axial one); a stiffer pipe would be capped there, with a
  warning and ``pipe_capped`` in the ground truth.
* The grasp (:class:`~.plugins.HandClamp`): node 0 at the hand, element 0's directors along the
  gripper axis (d3 = (cos phi_h, sin phi_h), as the MuJoCo chain's first link at rest), both
  with the hand's velocities: a clamp following :func:`~stringcast_lab.servo.hand_trajectory`.
  The first element is held straight along the gripper: the cord bends from node 1 on, and under
  a cast's tension (bending boundary layer sqrt(EI / T) ~ 2 mm, finer than an element) element 0's
  shear is the clamp's compliance.
* A drawn material (``lab.material``; docs/lab_physics.md, "The family of materials") sets EA
  (capped where a cast strains it < 0.05 %), the axial dashpot and the grasp: a ``clamp`` turns
  element 0 on a spring and dashpot towards the gripper axis, a ``pivot`` holds node 0 only.
* Start: the rod's own exact static equilibrium hanging from the first hand pose (Newton on
  its internal forces, :mod:`.statics`), then ``lab.settle_s`` of free dynamics: it settles to
  ~1e-11 m/s.
* Step: dt = 0.5 x 2 / omega_max over the elements' axial, bending, twist and shear-rotation
  modes (axial: dt = 0.5 l / sqrt(EA / lam)); 8.3e-6 s for the 3 mm, 20 g/m cord in 10 mm
  elements, recorded every ``lab.timestep_s`` (5e-5 s, 6 steps).

Material (SI; the cord's kind is not configured, so one braid stands for all):

===================  ==========================  =============================================
quantity             value                       source / reason
===================  ==========================  =============================================
linear density       ``density_g_per_m``         configured; mass = g/m x L (+ clay, pipes)
axial modulus E      1.0 GPa on pi d^2 / 4       fibres: nylon 6.6 2-5, polyester 10-15, cotton
                     (EA 7.1 kN at 3 mm,         5-12 GPa (Morton & Hearle, Physical Properties
                     4.9 kN at 2.5 mm)           of Textile Fibres, 4th ed. 2008); a braid keeps
                                                 a fraction (packing 0.5-0.7, braid angle,
                                                 bedding-in: McKenna, Hearle & O'Hear, Handbook
                                                 of Fibre Rope Technology 2004; Sry et al.,
                                                 Appl. Sci. 8: 1096, 2018); 3 mm braided cords
                                                 break at 1-2 kN (cotton 0.3-0.5) after 15-35 %
                                                 stretch: secant EA 3-13 kN, E 0.4-1.8 GPa.
                                                 1 GPa is the middle; 0.4 or 1.6 GPa moves the
                                                 demo's tip by < 5 mm (docs/lab_physics.md)
bending EI           ``bending_EI``              configured per type (2-3e-5 N m^2), as the
                                                 MuJoCo lab: E_b = EI / (pi d^4 / 64) = 5-10 MPa,
                                                 ~1/100 of E, as a braid's fibres slip in bending
                                                 (Papailiou, IEEE Trans. Power Deliv. 12, 1997)
shear, twist G       E_b / (2 (1 + 0.5))         the cross-section shears by the slip its bending
                                                 shows; nu 0.5, PyElastica's soft-rod default;
                                                 alpha 27/28 (Kaneko 1975, as PyElastica)
bending damping      ``bending_damping``         configured (2e-7 N m^2 s)
axial loss factor    0.03 at omega_1             assumed (fibre ropes lose a few % per load
                                                 cycle); 0.01 or 0.1 moves the tip < 3 mm
pipe (LDPE tube)     E 0.25 GPa, 920 kg/m^3      LDPE 0.1-0.35 GPa, 910-940 kg/m^3 (Mark, ed.,
                                                 Physical Properties of Polymers Handbook 2007)
air                  ``lab.air``                 1.2 kg/m^3, 1.8e-5 Pa s
===================  ==========================  =============================================
"""
from .material import RodMaterial, rod_material
from .sim import RodSim, simulate_rod

__all__ = ["RodMaterial", "RodSim", "rod_material", "simulate_rod"]
