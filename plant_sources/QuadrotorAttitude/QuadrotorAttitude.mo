within;
model QuadrotorAttitude
  "Quadrotor attitude dynamics (paper eq. 25): roll, pitch, yaw with cross-axis coupling"
  // Same equations as model.c.
  parameter Real Ix(unit = "kg.m2") = 0.4 "Moment of inertia about x";
  parameter Real Iy(unit = "kg.m2") = 0.4 "Moment of inertia about y";
  parameter Real Iz(unit = "kg.m2") = 0.8 "Moment of inertia about z";
  parameter Real phi0(unit = "rad") = 0.0 "Initial roll angle";
  parameter Real theta0(unit = "rad") = 0.0 "Initial pitch angle";
  parameter Real psi0(unit = "rad") = 0.0 "Initial yaw angle";
  parameter Real p0(unit = "rad/s") = 0.0 "Initial roll rate";
  parameter Real q0(unit = "rad/s") = 0.0 "Initial pitch rate";
  parameter Real r0(unit = "rad/s") = 0.0 "Initial yaw rate";
  input Real U_phi(start = 0.0, unit = "N.m") "Roll torque";
  input Real U_theta(start = 0.0, unit = "N.m") "Pitch torque";
  input Real U_psi(start = 0.0, unit = "N.m") "Yaw torque";
  output Real phi(start = phi0, fixed = true, unit = "rad") "Roll angle";
  output Real theta(start = theta0, fixed = true, unit = "rad") "Pitch angle";
  output Real psi(start = psi0, fixed = true, unit = "rad") "Yaw angle";
  output Real p(start = p0, fixed = true, unit = "rad/s") "Roll rate";
  output Real q(start = q0, fixed = true, unit = "rad/s") "Pitch rate";
  output Real r(start = r0, fixed = true, unit = "rad/s") "Yaw rate";
equation
  der(phi) = p;
  der(theta) = q;
  der(psi) = r;
  der(p) = (Iy - Iz)/Ix*q*r + U_phi/Ix;
  der(q) = (Iz - Ix)/Iy*p*r + U_theta/Iy;
  der(r) = (Ix - Iy)/Iz*p*q + U_psi/Iz;
end QuadrotorAttitude;
