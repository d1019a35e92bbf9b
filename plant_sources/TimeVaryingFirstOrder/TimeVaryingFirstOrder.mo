within;
model TimeVaryingFirstOrder
  "Time-varying first-order plant dx/dt = a(t) x + u, a(t) = a_offset + a_amplitude (sin(2 pi a_frequency t) + 1) (paper eq. 22-23)"
  // Same equations as model.c. pi is declared here rather than taken from Modelica.Constants so
  // that the model needs no library.
  parameter Real a_offset(unit = "1/s") = 0.5 "Offset of a(t)";
  parameter Real a_amplitude(unit = "1/s") = 0.25 "Amplitude of a(t)";
  parameter Real a_frequency(unit = "Hz") = 0.1 "Frequency of a(t) (0.1 Hz gives sin(0.2 pi t))";
  parameter Real x0 = 0.0 "Initial state";
  input Real u(start = 0.0) "Control input";
  output Real y "Plant output y = x";
  output Real a_t(unit = "1/s") "Current pole a(t)";
protected
  constant Real pi = 3.14159265358979323846;
  Real x(start = x0, fixed = true) "State";
equation
  a_t = a_offset + a_amplitude*(sin(2*pi*a_frequency*time) + 1);
  der(x) = a_t*x + u;
  y = x;
end TimeVaryingFirstOrder;
