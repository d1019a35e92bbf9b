within;
model LinearBatch
  "y = N(s)/D(s) e^(-sL) u: one parameterised linear plant for Astrom & Hagglund's PID test batch"
  // Same equations as model.c (controllable canonical form of order n, the highest power with den[n] <> 0;
  // the FMU is built from the C source). N(s) = sum num[k+1] s^k (k = 0..3), D(s) = sum den[k+1] s^k (k = 0..8).
  parameter Real num[4] = {1, 0, 0, 0} "Coefficients of s^0..s^3 in N(s)";
  parameter Real den[9] = {1, 1, 0, 0, 0, 0, 0, 0, 0} "Coefficients of s^0..s^8 in D(s)";
  parameter Real L(unit = "s") = 0 "Dead time at the input";
  parameter Integer n = max({if den[k] <> 0 then k - 1 else 0 for k in 1:9}) "Order of D(s)";
  input Real u(start = 0) "Plant input";
  output Real y "Plant output";
protected
  Real x[8](each start = 0, each fixed = true) "Canonical states (x[1]: D(s) x1 = u)";
  Real ud "Delayed input";
equation
  ud = delay(u, L);
  for i in 1:8 loop
    if i < n then
      der(x[i]) = x[i + 1];
    elseif i == n then
      der(x[i]) = (ud - sum(den[k] * x[k] for k in 1:n)) / den[n + 1];
    else
      der(x[i]) = 0;
    end if;
  end for;
  y = sum(num[k] * x[k] for k in 1:min(n, 4));
end LinearBatch;
