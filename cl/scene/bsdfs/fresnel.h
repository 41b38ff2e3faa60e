/* fresnel.h: Fresnel reflectance of conductors (complex IOR) and dielectrics, shared by the
 * materials in cl/scene/bsdfs/ (and tested on their own in tests/test_sampling.py). Needs
 * nothing but core/common.h; the host's float64 twin is pyclpt/buffers/materials.py. */
#ifndef PYCLPT_BSDFS_FRESNEL_H
#define PYCLPT_BSDFS_FRESNEL_H

#include "core/common.h"

/* Unpolarised Fresnel reflectance of a conductor with complex IOR eta + i k (cos_i >= 0). */
static inline float fresnel_conductor1(float cos_i, float eta, float k) {
    float c2 = cos_i * cos_i, s2 = 1.0f - c2;
    float eta2 = eta * eta, k2 = k * k;
    float t0 = eta2 - k2 - s2;
    float a2pb2 = m_sqrt(m_max(t0 * t0 + 4.0f * eta2 * k2, 0.0f));
    float t1 = a2pb2 + c2;
    /* a^2 = (a2pb2 + t0) / 2; for t0 < 0 its cancellation (exactly 0 for k = 0 or eta = 0, a mirror) turns
     * into 4 eta^2 k^2 / (a2pb2 - t0), which the contraction into FMAs of GPU compilers cannot leave at
     * ~1e-8 instead of 0 (whose square root made a mirror 0.9995). */
    float a2 = t0 >= 0.0f ? 0.5f * (a2pb2 + t0) : 2.0f * eta2 * k2 / (a2pb2 - t0);
    float a = m_sqrt(m_max(a2, 0.0f));
    float t2 = 2.0f * cos_i * a;
    float rs = (t1 - t2) / (t1 + t2);
    float t3 = c2 * a2pb2 + s2 * s2;
    float t4 = t2 * s2;
    float rp = rs * (t3 - t4) / (t3 + t4);
    return 0.5f * (rp + rs);
}

/* The same per RGB channel. */
static inline vec3 fresnel_conductor(float cos_i, vec3 eta, vec3 k) {
    return v3(fresnel_conductor1(cos_i, eta.x, k.x), fresnel_conductor1(cos_i, eta.y, k.y),
              fresnel_conductor1(cos_i, eta.z, k.z));
}

/* Dielectric Fresnel reflectance for a signed cos_i (negative: from inside), eta = int/ext.
 * Returns F and the signed cosine of the refracted direction and eta_ti = 1/eta_it. */
static inline float fresnel_dielectric(float cos_i, float eta, float* cos_t, float* eta_ti) {
    bool outside = cos_i >= 0.0f;
    float eta_it = outside ? eta : 1.0f / eta;
    *eta_ti = 1.0f / eta_it;
    float cos_t_sqr = 1.0f - (1.0f - cos_i * cos_i) * (*eta_ti) * (*eta_ti);
    float ci = m_abs(cos_i);
    if (cos_t_sqr <= 0.0f) {
        *cos_t = 0.0f;
        return 1.0f;
    }
    float ct = m_sqrt(cos_t_sqr);
    float a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
    float a_p = (eta_it * ci - ct) / (eta_it * ci + ct);
    *cos_t = outside ? -ct : ct;
    /* at most 1: a GPU compiler's FMAs can round it just above (1 - F then negative) */
    return m_min(0.5f * (a_s * a_s + a_p * a_p), 1.0f);
}

/* F alone, for cos_i >= 0 on the outside of an interface int/ext = eta. */
static inline float fresnel_dielectric_f(float cos_i, float eta) {
    float ct, eti;
    return fresnel_dielectric(cos_i, eta, &ct, &eti);
}

#endif
