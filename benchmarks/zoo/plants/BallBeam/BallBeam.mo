within;
model BallBeam "Ball and beam with a servo lag (Hauser, Sastry & Kokotovic 1992)"
  // Same equations as model.c.
  parameter Real B = 5 / 7 "m / (J_b / r_b^2 + m)";
  parameter Real g(unit = "m/s2") = 9.81;
  parameter Real tau_s(unit = "s") = 0.05 "Servo time constant";
  parameter Real p0(unit = "m") = 0 "Start position";
  input Real theta_c(unit = "rad", start = 0) "Beam angle command";
  output Real p(unit = "m", start = p0, fixed = true) "Ball position";
protected
  Real v(start = 0, fixed = true);
  Real theta(start = 0, fixed = true);
equation
  der(theta) = (theta_c - theta) / tau_s;
  der(p) = v;
  der(v) = B * (p * der(theta)^2 + g * sin(theta));
end BallBeam;
